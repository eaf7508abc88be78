"""The nested-mapping helpers every parameter writer shares (pipeline/mappings.py)."""

from __future__ import annotations

import pytest

from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.mappings import deep_merge, set_path


def test_set_path_creates_the_mappings_on_the_way_and_keeps_siblings():
    target = {"register": {"metric": {"name": "jt"}}}
    assert set_path(target, "register.metric.alpha", 1.5) is target
    set_path(target, ["prune", "min_area_fraction"], 0.1)
    assert target == {"register": {"metric": {"name": "jt", "alpha": 1.5}}, "prune": {"min_area_fraction": 0.1}}


def test_set_path_refuses_to_descend_into_a_value_and_names_where():
    with pytest.raises(ConfigError, match=r"--set register\.metric\.alpha: 'metric' is not a mapping"):
        set_path({"register": {"metric": "jt"}}, "register.metric.alpha", 2.0, "--set register.metric.alpha")


def test_deep_merge_is_key_by_key_top_wins_and_leaves_both_inputs_alone():
    base = {"schedule": [1, 2], "check": {"grid": 13, "margin": 0.005}, "seed": 0}
    top = {"check": {"grid": 5}, "seed": 3, "schedule": [9]}
    merged = deep_merge(base, top)
    assert merged == {"schedule": [9], "check": {"grid": 5, "margin": 0.005}, "seed": 3}
    assert base == {"schedule": [1, 2], "check": {"grid": 13, "margin": 0.005}, "seed": 0}
    assert top == {"check": {"grid": 5}, "seed": 3, "schedule": [9]}
    assert deep_merge({"a": {"b": 1}}, {"a": 2}) == {"a": 2}  # a value replaces a mapping, and the reverse
    assert deep_merge({"a": 2}, {"a": {"b": 1}}) == {"a": {"b": 1}}
