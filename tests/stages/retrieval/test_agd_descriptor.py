"""The ``agd`` method's descriptor (intrinsic skeleton + heat-kernel endpoint signatures) is a similarity invariant."""

from __future__ import annotations

import numpy as np

from topomatch.stages.mesh.io import read_mesh
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.morse.agd import average_geodesic_distance
from topomatch.stages.reeb.level_sets import level_values
from topomatch.stages.reeb.prune import make_skeleton
from topomatch.stages.reeb.reeb_graph import reeb_graph
from topomatch.stages.retrieval.descriptor import EndpointHKSParams, endpoint_hks_descriptor
from topomatch.stages.spectral.spectrum import mesh_spectrum
from tests_paths import BUNDLED_MESHES


def describe(mesh: Mesh) -> np.ndarray:
    f = average_geodesic_distance(mesh.V, mesh.F).values
    skeleton = make_skeleton(reeb_graph(mesh.V, mesh.F, f, level_values(f, 22)), 0.01)
    d = endpoint_hks_descriptor(skeleton, mesh_spectrum(mesh, 40), params=EndpointHKSParams()).descriptor
    return d.data[np.lexsort(d.data.T[::-1])]


def test_invariant_to_rotation_translation_scale():
    from topomatch.stages.mesh.decimate import decimate_mesh

    mesh = decimate_mesh(read_mesh(BUNDLED_MESHES / "odedstein_human_woman.obj.gz")[0], 4000).mesh
    R = np.linalg.qr(np.random.default_rng(5).standard_normal((3, 3)))[0]
    moved = Mesh(0.3 * mesh.V @ R.T + [10.0, 0.0, -4.0], mesh.F, name="moved")
    a, b = describe(mesh), describe(moved)
    assert a.shape == b.shape and a.shape[1] == 3 + EndpointHKSParams().n_times
    assert len(a) >= 5  # head, hands, feet
    np.testing.assert_allclose(a, b, atol=1e-6)
