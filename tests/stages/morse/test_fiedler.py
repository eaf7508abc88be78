"""The ``fiedler`` stage: phi2 as a Morse function, its summary, parameters and known shapes."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.errors import ConfigError, InputError
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.morse.function import MorseFunction
from topomatch.stages.morse.fiedler import FiedlerParams, fiedler, fiedler_function


def test_stage_is_registered_with_its_data_flow():
    from topomatch.pipeline.registry import get_stage

    spec = get_stage("fiedler")
    assert spec.consumes == ("mesh",) and spec.produces == ("function",)
    assert spec.params is FiedlerParams


def test_result_function_and_summary(bundled_mesh):
    mesh = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    result = fiedler(mesh, params=FiedlerParams())
    f = result.function
    assert isinstance(f, MorseFunction) and f.kind == "fiedler" and f.root is None
    assert f.values.shape == (mesh.n_vertices,) and f.values.dtype == np.float64
    assert np.array_equal(result.values, f.values)
    assert result.eigenvalues.shape == (3,) and result.eigenvalues[0] == 0.0
    np.testing.assert_array_equal(result.eigenpairs.fiedler, f.values)
    s = result.summary()
    assert s["lambda2"] == result.eigenvalues[1] and s["lambda3"] == result.eigenvalues[2]
    assert s["lambda2"] < s["lambda3"] and s["gap23"] > 0
    assert s["method"] == "shift_invert" and s["seconds"] > 0 and s["skewness2"] > 0
    assert s["residual"] <= 1e-5


def test_elongated_shape_phi2_follows_the_long_axis(shapes):
    """An ellipsoid with axes 4 : 1 : 1 -- phi2 is (nearly) a monotone function of x."""
    sphere = shapes.icosphere(3)
    mesh = Mesh(sphere.V * np.array([4.0, 1.0, 1.0]), sphere.F, name="ellipsoid")
    f = fiedler(mesh, params=FiedlerParams(n_eigenpairs=2)).values
    assert abs(np.corrcoef(f, mesh.V[:, 0])[0, 1]) > 0.97


def test_parameters(bundled_mesh):
    mesh = bundled_mesh("odedstein_hand_lowres.obj.gz")
    full = fiedler(mesh, params=FiedlerParams.parse({"n_eigenpairs": 5}, "stages[1].fiedler"))
    assert full.eigenvalues.shape == (5,)
    vor = fiedler(mesh, params=FiedlerParams.parse({"mass": "voronoi", "method": "lobpcg"}, "stages[1].fiedler"))
    assert vor.summary()["mass"] == "voronoi" and vor.summary()["method"] == "lobpcg"
    # the lumped mass changes lambda2 a little, not the shape of phi2
    assert vor.summary()["lambda2"] == pytest.approx(full.summary()["lambda2"], rel=0.05)
    assert abs(np.corrcoef(vor.values, full.values)[0, 1]) > 0.99
    flipped = fiedler(mesh, params=FiedlerParams(sign_rule="max_abs"))
    v = flipped.values
    assert v[np.argmax(np.abs(v))] > 0
    for bad in ({"method": "magic"}, {"n_eigenpairs": 1}, {"tol": 0.5}, {"mass": "lumped"}, {"seed": 1}):
        with pytest.raises(ConfigError, match="stages\\[1\\].fiedler"):
            FiedlerParams.parse(bad, "stages[1].fiedler")


def test_bad_mesh_errors_name_the_mesh(shapes):
    mesh = shapes.disjoint_union(shapes.octahedron(), shapes.octahedron(), name="pair")
    with pytest.raises(InputError, match="pair.*connected components"):
        fiedler(mesh, params=FiedlerParams())


def test_morse_stage_dispatches_to_fiedler(bundled_mesh):
    from topomatch.stages.morse.stage import MorseParams, morse

    mesh = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    f = morse(mesh, params=MorseParams(function="fiedler")).function
    np.testing.assert_array_equal(f.values, fiedler_function(mesh).values)
    assert f.kind == "fiedler"


def test_a_single_triangle_is_too_small_for_a_spectral_function():
    tri = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]), name="tri")
    with pytest.raises(InputError, match="tri: the mesh has 3 vertices and 1 faces: too few for 3 Laplace"):
        fiedler(tri, params=FiedlerParams())
