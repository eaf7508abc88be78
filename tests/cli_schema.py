"""Validating ``--json`` outputs against the shipped schema (topomatch/cli/schema.json), for any test."""

from __future__ import annotations

import json

from topomatch.cli.common import SCHEMA_PATH

SCHEMA = json.loads(SCHEMA_PATH.read_text())


def check(document: dict, definition: str) -> None:
    """Validate ``document`` against ``$defs/definition`` (jsonschema when installed, else the required keys)."""
    try:
        import jsonschema
    except ImportError:  # pragma: no cover - jsonschema is a test dependency
        spec = SCHEMA["$defs"][definition]
        assert set(spec["required"]) <= set(document)
        if spec.get("additionalProperties") is False:
            assert set(document) <= set(spec["properties"])
        return
    schema = {k: v for k, v in SCHEMA.items() if k != "anyOf"} | {"$ref": f"#/$defs/{definition}"}
    jsonschema.Draft202012Validator(schema).validate(document)
    jsonschema.Draft202012Validator(SCHEMA).validate(document)  # and the top-level schema accepts it
