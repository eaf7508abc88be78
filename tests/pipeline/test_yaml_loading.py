"""YAML is loaded strictly and within bounds: duplicate keys, alias bombs, deep nesting, size."""

from __future__ import annotations

import time

import pytest

from topomatch.pipeline.config import apply_overrides, read_yaml
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.yaml_loading import MAX_DEPTH, MAX_NODES, load_yaml


def laughs(levels: int) -> str:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def test_duplicate_keys_name_the_key_and_both_lines():
    with pytest.raises(ConfigError, match="duplicate key 'stages' on lines 2 and 4"):
        load_yaml("name: x\nstages: [load]\ninputs: {}\nstages: [load, clean]\n")
    with pytest.raises(ConfigError, match="duplicate key 'sigma'"):
        load_yaml("noise: {sigma: 1, sigma: 2}\n")


@pytest.mark.parametrize("levels", [9, 12])
def test_an_alias_bomb_is_refused_at_once(levels):
    t = time.perf_counter()
    with pytest.raises(ConfigError, match=f"more than {MAX_NODES:,} values"):
        load_yaml(laughs(levels))
    assert time.perf_counter() - t < 1.0


def test_modest_aliases_are_fine():
    data = load_yaml(laughs(3))
    assert len(data["a2"]) == 9 and data["a2"][0][0][0] == "lol"


@pytest.mark.parametrize("text", ["x: " + "[" * 5000 + "]" * 5000, "x: " + "{a: " * 200 + "1" + "}" * 200])
def test_deep_nesting_is_refused(text):
    with pytest.raises(ConfigError, match=f"nested more than {MAX_DEPTH} levels"):
        load_yaml(text)


def test_block_nesting_is_bounded_too():
    text = "".join("  " * i + f"k{i}:\n" for i in range(100)) + "  " * 100 + "v: 1\n"
    with pytest.raises(ConfigError, match="nested"):
        load_yaml(text)


def test_errors_name_the_file_and_overrides(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("name: x\nname: y\n")
    with pytest.raises(ConfigError, match="bad.yaml: duplicate key 'name'"):
        read_yaml(path)
    with pytest.raises(ConfigError, match=r"--set 'noise.sigma=\{a: 1, a: 2\}': the value is duplicate key"):
        apply_overrides({"stages": ["noise"]}, ["noise.sigma={a: 1, a: 2}"])
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_yaml("a: [1, 2\n")
