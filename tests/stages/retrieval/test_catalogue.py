"""The method catalogue: every consumer reads it, and a new descriptor is one module plus one record
(the worked example of docs/engine.md, run end to end)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from pydantic import Field

import topomatch
from topomatch.cli import build_parser
from topomatch.pipeline.contract import Params, stage
from topomatch.pipeline.registry import get_stage, register_module
from topomatch.stages.retrieval import catalogue
from topomatch.stages.retrieval.baselines.vectors import pairwise
from topomatch.stages.retrieval.catalogue import CLEAN_CHAIN, METHODS, Method
from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult
from tests_paths import BUNDLED_MESHES


# --------------------------------------------------------------------------- the docs' example module


class FiedlerHistogramParams(Params):
    bins: int = Field(32, ge=2, description="histogram bins of phi_2 / max |phi_2|")


def distance_matrix(X, Y=None):
    """(n, m) L1 distances of the histograms."""
    return pairwise(X, Y, metric="cityblock")


@stage("fiedler_histogram", params=FiedlerHistogramParams, version=1, consumes=("function",),
       produces=("descriptor",))
def fiedler_histogram(function, *, params):
    """Histogram of the (sign-fixed) Fiedler vector."""
    x = function.values / np.abs(function.values).max()
    h = np.histogram(x, bins=params.bins, range=(-1, 1))[0]
    return DescriptorResult(Descriptor("vector", h / h.sum()))


RECORD = Method("fh", "Fiedler-vector histogram", "vector",
                CLEAN_CHAIN + ({"morse": {"function": "fiedler"}}, "fiedler_histogram"), distance=distance_matrix)


@pytest.fixture
def with_fh(monkeypatch):
    register_module(sys.modules[__name__])
    monkeypatch.setitem(METHODS, "fh", RECORD)
    yield


def test_a_new_descriptor_is_one_module_and_one_record(with_fh, tmp_path, capsys):
    assert get_stage("fiedler_histogram").func is fiedler_histogram
    paths = [BUNDLED_MESHES / n for n in ("torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz")]
    report = topomatch.index(paths, tmp_path / "s.db", method="fh", workers=1)
    assert report.parts[0].done == 3
    hit = topomatch.open_index(tmp_path / "s.db").query(paths[1], k=1, method="fh").results[0]
    assert hit["path"] == str(paths[1].resolve()) and hit["dissimilarity"] == 0.0
    assert topomatch.match(paths[0], paths[0], method="fh").dissimilarity == 0.0
    commands = next(a for a in build_parser()._actions if a.dest == "command")
    method = next(a for a in commands.choices["query"]._actions if a.dest == "method")
    assert "fh" in method.choices and "Fiedler-vector histogram" in method.help


def test_every_record_is_complete():
    for m in METHODS.values():
        assert m.title and m.kind in ("endpoints", "vector", "fusion")
        if m.kind == "fusion":
            assert m.fusion is not None and not m.chain and set(m.fusion.parts) <= set(METHODS)
            assert all(METHODS[p].kind != "fusion" for p in m.fusion.parts)
        else:
            assert m.chain and m.fusion is None and m.parts == (m.name,)
            assert (m.distance is not None) == (m.kind == "vector")
            last = m.chain[-1]
            assert "descriptor" in get_stage(last if isinstance(last, str) else next(iter(last))).produces
    assert catalogue.DEFAULT_METHOD in METHODS and METHODS[catalogue.DEFAULT_PAIR_METHOD].kind != "fusion"
    with pytest.raises(topomatch.ConfigError, match="unknown retrieval method 'nope'; methods: rgpd"):
        catalogue.get_method("nope")


@pytest.mark.parametrize("name", ["rgpd", "srg", "agd"])
def test_a_shape_without_endpoints_is_not_at_distance_zero_from_everything(name):
    """The thesis methods' default unmatched cost is positive: a skeleton with no endpoints is as far
    from one with n endpoints as n unmatched endpoints cost (and at 0 only from another such shape)."""
    from topomatch.stages.retrieval.ranking import dissimilarities

    method = METHODS[name]
    width = 3 if method.name != "agd" else 3 + 8
    rng = np.random.default_rng(0)
    none = Descriptor("endpoints", np.zeros((0, width)), 0)
    others = [Descriptor("endpoints", rng.random((n, width)), n) for n in (2, 5, 9)]
    d = dissimilarities(none, others + [none], method)
    assert method.unmatched_cost > 0
    np.testing.assert_allclose(d, [2 * method.unmatched_cost, 5 * method.unmatched_cost, 9 * method.unmatched_cost, 0])
