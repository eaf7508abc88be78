"""The stage registry: every stage is registered with typed params that have usable defaults."""

from __future__ import annotations

import pytest

from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.registry import REPORTS, describe_params, discover, get_stage

MINIMAL_PARAMS = {"decimate": {"ratio": 0.5}, "decimate_crosscheck": {"ratio": 0.5}}
FOUNDATION_STAGES = {"load", "clean", "decimate", "decimate_crosscheck", "noise", "transform", "measures"}


def test_foundation_stages_are_registered():
    assert FOUNDATION_STAGES <= set(discover())


@pytest.mark.parametrize("name", sorted(FOUNDATION_STAGES))
def test_stage_spec_is_complete(name):
    spec = get_stage(name)
    assert isinstance(spec.version, int) and spec.version >= 1
    assert spec.doc, f"stage {name} needs a one-line docstring"
    rows = describe_params(spec.params)
    for field, type_name, default, _ in rows:
        assert type_name, field
    # params are frozen: a stage cannot mutate its configuration
    params = spec.params.parse(MINIMAL_PARAMS.get(name, {}), name)
    with pytest.raises(Exception):
        setattr(params, next(iter(spec.params.model_fields)), None)


def test_unknown_stage_error():
    with pytest.raises(ConfigError, match="unknown stage 'nope'"):
        get_stage("nope")


def test_reports_registered():
    discover()
    assert {"table", "line_plot", "mesh_gallery"} <= set(REPORTS)
