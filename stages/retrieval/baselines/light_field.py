"""The light field descriptor (Chen, Tian, Shen, Ouhyoung 2003): silhouettes seen from a dodecahedron's vertices.

D.-Y. Chen, X.-P. Tian, Y.-T. Shen, M. Ouhyoung, "On visual similarity based 3D model retrieval", Computer
Graphics Forum 22(3), 2003 (the strongest classic descriptor of the Princeton Shape Benchmark). Two shapes are
alike if they look alike from every side; a *light field* is the set of silhouettes seen by cameras on the
vertices of a dodecahedron about the shape, compared under the dodecahedron's rotations.

Definition used here
--------------------
1. **Normalisation.** The surface's area-weighted centroid to the origin, the farthest vertex from it to
   radius 1 (the bounding sphere about the centroid): every silhouette lies in the unit disc of its image.
2. **Views.** A dodecahedron's 20 vertices are 10 axes (antipodal vertices see mirrored silhouettes of an
   orthographic projection, which the features below do not tell apart). Each of ``light_fields`` [5]
   dodecahedra (the first unrotated, the others by fixed random rotations, seed 0) gives 10 silhouettes of
   ``resolution`` x ``resolution`` [96] pixels over [-1, 1]^2, by orthographic ray casting
   (``open3d.t.geometry.RaycastingScene``, one call for all rays; a pixel is inside if its ray hits a triangle).
3. **Features of a silhouette** (:data:`FEATURES` = 46): the magnitudes of its 36 Zernike moments of order
   n <= 10 on the unit disc (invariant to rotation in the image plane and to reflection), and the magnitudes of
   the Fourier coefficients 1-10 of its centroid distance (the farthest silhouette pixel from the silhouette's
   centroid in each of 64 directions) over the mean distance (coefficient 0), as the paper's 35 Zernike and 10
   Fourier descriptors (the paper quantises them to 8 bits; here they stay float32).
4. **Dissimilarity.** Two light fields compare as the smallest, over the 60 rotations of the dodecahedron
   (each a permutation of the 10 axes, :func:`axis_permutations`), sum over the 10 axes of the L1 distance of
   the axes' features; two shapes as the smallest over every pair of their light fields (the paper's rule,
   10 x 10 light fields there: fewer here, for cost).

Zernike moments are computed here (a basis image per moment, a matrix product per batch of silhouettes): no
installed library computes them (scikit-image does not; mahotas would be a new dependency for 20 lines).

Checks (tested): the unit disc has A_00 = 1 and every other moment ~0; a shape rotated by a dodecahedron
symmetry has the same light field up to the axis permutation; a rotated, scaled, shifted mesh is at distance
~0 from itself.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, stage
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval.baselines.sampling import area_centroid_and_rms_radius, checked_areas
from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult

ZERNIKE_ORDER = 10
FOURIER_COEFFICIENTS = 10
CONTOUR_DIRECTIONS = 64
AXES = 10
ZERNIKE_INDICES = tuple((n, m) for n in range(ZERNIKE_ORDER + 1) for m in range(n + 1) if (n - m) % 2 == 0)
FEATURES = len(ZERNIKE_INDICES) + FOURIER_COEFFICIENTS
"""Features of one silhouette: 36 Zernike magnitudes and 10 Fourier magnitudes."""
BLOCK = 64
"""Shapes compared at once by :func:`distance_matrix` at 5 light fields (fewer at more: a block holds L^2 x 100 x 46
floats a shape, ~56 MB at 5)."""


class LightFieldParams(Params):
    """Parameters of the light field descriptor (:func:`descriptor`)."""

    light_fields: int = Field(5, ge=1, le=20, description="dodecahedra (differently rotated) per shape; two shapes "
                                                          "compare at their best pair of light fields")
    resolution: int = Field(96, ge=16, le=512, description="pixels per side of a silhouette image over [-1, 1]^2")
    seed: int = Field(0, ge=0, description="seed of the rotations of the light fields after the first")


def dodecahedron_axes() -> np.ndarray:
    """The 10 axes through a regular dodecahedron's antipodal vertex pairs, (10, 3) unit vectors."""
    phi = (1 + math.sqrt(5)) / 2
    vertices = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    for a in (-1 / phi, 1 / phi):
        for b in (-phi, phi):
            vertices += [(0, a, b), (a, b, 0), (b, 0, a)]
    V = np.array(vertices, dtype=np.float64)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    axes: list[np.ndarray] = []
    for v in V:
        if not any(abs(v @ a) > 1 - 1e-9 for a in axes):
            axes.append(v)
    return np.array(axes)


def _rotation(axis, angle: float) -> np.ndarray:
    """Rotation matrix by ``angle`` about ``axis`` (Rodrigues), (3, 3)."""
    k = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def dodecahedron_rotations() -> np.ndarray:
    """The 60 rotations that map the dodecahedron to itself, (60, 3, 3): the closure of a fifth of a turn about
    a face's axis and a third of a turn about a vertex's axis."""
    phi = (1 + math.sqrt(5)) / 2
    generators = [_rotation((0, phi, 1), 2 * math.pi / 5), _rotation((1, 1, 1), 2 * math.pi / 3)]
    group = [np.eye(3)]
    frontier = [np.eye(3)]
    while frontier:
        new = []
        for R in frontier:
            for G in generators:
                P = G @ R
                if not any(np.allclose(P, Q, atol=1e-9) for Q in group):
                    group.append(P)
                    new.append(P)
        frontier = new
    return np.array(group)


def axis_permutations() -> np.ndarray:
    """For each of the 60 rotations, the axis each of the 10 axes goes to, (60, 10) int."""
    axes = dodecahedron_axes()
    rotated = np.einsum("rij,aj->rai", dodecahedron_rotations(), axes)
    return np.abs(rotated @ axes.T).argmax(axis=2)


def light_field_rotations(count: int, seed: int) -> np.ndarray:
    """The rotation of each light field, (count, 3, 3): the identity, then uniform random rotations (QR of a
    Gaussian matrix, signs fixed, det +1) from ``numpy.random.default_rng(seed)``."""
    rng = np.random.default_rng(seed)
    out = [np.eye(3)]
    while len(out) < count:
        Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
        Q = Q * np.sign(np.diag(R))
        out.append(Q if np.linalg.det(Q) > 0 else -Q)
    return np.array(out[:count])


def normalised_vertices(mesh: Mesh) -> np.ndarray:
    """Vertices with the area-weighted centroid at the origin and the farthest vertex at radius 1, (n, 3)."""
    centroid, _ = area_centroid_and_rms_radius(mesh.V, mesh.F, checked_areas(mesh))
    V = mesh.V - centroid
    radius = np.linalg.norm(V, axis=1).max()
    return V / radius


def silhouettes(V: np.ndarray, F: np.ndarray, directions: np.ndarray, resolution: int) -> np.ndarray:
    """Orthographic silhouettes of the mesh (``V`` normalised to the unit ball) seen along each direction,
    (d, resolution, resolution) bool; pixel (i, j) is at ``x_j u + y_i w`` with ``x, y`` pixel centres in
    [-1, 1] and ``(u, w)`` an orthonormal basis of the plane normal to the direction."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(V, dtype=np.float32)),
                        o3d.core.Tensor(np.ascontiguousarray(F, dtype=np.uint32)))
    c = (np.arange(resolution) + 0.5) / resolution * 2 - 1
    X, Y = np.meshgrid(c, c)
    rays = []
    for d in directions:
        helper = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
        u = np.cross(d, helper)
        u /= np.linalg.norm(u)
        w = np.cross(d, u)
        origins = 2.0 * d + X.reshape(-1, 1) * u + Y.reshape(-1, 1) * w
        rays.append(np.hstack([origins, np.broadcast_to(-d, origins.shape)]))
    hits = scene.cast_rays(o3d.core.Tensor(np.vstack(rays).astype(np.float32)))["t_hit"].numpy()
    return np.isfinite(hits).reshape(len(directions), resolution, resolution)


def _radial(n: int, m: int, r: np.ndarray) -> np.ndarray:
    """Zernike radial polynomial R_nm(r)."""
    out = np.zeros_like(r)
    for s in range((n - m) // 2 + 1):
        coefficient = (-1) ** s * math.factorial(n - s) / (
            math.factorial(s) * math.factorial((n + m) // 2 - s) * math.factorial((n - m) // 2 - s))
        out += coefficient * r ** (n - 2 * s)
    return out


def zernike_basis(resolution: int) -> np.ndarray:
    """Conjugate Zernike basis over the pixels of a [-1, 1]^2 image, (36, resolution^2) complex, scaled so that
    ``basis @ image.ravel()`` is ``A_nm = (n + 1) / pi * sum f V*_nm dA`` (0 outside the unit disc)."""
    c = (np.arange(resolution) + 0.5) / resolution * 2 - 1
    X, Y = np.meshgrid(c, c)
    r, t = np.hypot(X, Y).ravel(), np.arctan2(Y, X).ravel()
    inside = r <= 1
    area = (2.0 / resolution) ** 2
    rows = [(n + 1) / math.pi * area * inside * _radial(n, m, r) * np.exp(-1j * m * t) for n, m in ZERNIKE_INDICES]
    return np.array(rows)


def contour_fourier(images: np.ndarray) -> np.ndarray:
    """Magnitudes of the Fourier coefficients 1..10 of each silhouette's centroid distance over coefficient 0,
    (d, 10); the centroid distance in each of 64 directions is that of the farthest pixel centre (all 0 for a
    silhouette of fewer than 3 pixels)."""
    out = np.zeros((images.shape[0], FOURIER_COEFFICIENTS))
    for k in range(images.shape[0]):
        ys, xs = np.nonzero(images[k])
        if xs.size < 3:  # no outline to speak of: a dot's centroid distance is no shape
            continue
        x, y = xs - xs.mean(), ys - ys.mean()
        bins = ((np.arctan2(y, x) + math.pi) / (2 * math.pi) * CONTOUR_DIRECTIONS).astype(np.int64) % CONTOUR_DIRECTIONS
        radius = np.zeros(CONTOUR_DIRECTIONS)
        np.maximum.at(radius, bins, np.hypot(x, y) + 0.5)
        spectrum = np.abs(np.fft.rfft(radius))
        out[k] = spectrum[1:FOURIER_COEFFICIENTS + 1] / spectrum[0]
    return out


def features(images: np.ndarray) -> np.ndarray:
    """The 46 features of each silhouette, (d, 46) float32: Zernike magnitudes, then Fourier magnitudes."""
    basis = zernike_basis(images.shape[1])
    zernike = np.abs(images.reshape(images.shape[0], -1).astype(np.float64) @ basis.T)
    return np.hstack([zernike, contour_fourier(images)]).astype(np.float32)


def descriptor(mesh: Mesh, params: LightFieldParams | None = None) -> np.ndarray:
    """The light fields of ``mesh``: (light_fields * 10 * 46,) float32, light field by light field, axis by axis.

    Raises
    ------
    InputError
        Empty mesh, bad indices, non-finite coordinates or zero area (names the mesh).
    """
    params = LightFieldParams() if params is None else params
    V = normalised_vertices(mesh)
    axes = dodecahedron_axes()
    directions = np.einsum("lij,aj->lai", light_field_rotations(params.light_fields, params.seed), axes)
    images = silhouettes(V, mesh.F, directions.reshape(-1, 3), params.resolution)
    return features(images).ravel()


def _views(X) -> np.ndarray:
    """Descriptors (n, L * 10 * 46) (or one, 1-D) as (n, L, 10, 46) float32."""
    X = np.asarray(X, dtype=np.float32)
    X = X.reshape(1, -1) if X.ndim == 1 else X
    if X.shape[1] % (AXES * FEATURES):
        raise ValueError(f"light field descriptors have a multiple of {AXES * FEATURES} entries, got {X.shape[1]}")
    return X.reshape(X.shape[0], -1, AXES, FEATURES)


def distance_matrix(X, Y=None) -> np.ndarray:
    """Light field dissimilarity of every pair (module docstring, point 4): ``X`` (n, d), ``Y`` (m, d) (default
    ``X``) -> (n, m) float64."""
    A = _views(X)
    B = A if Y is None else _views(Y)
    if A.shape[1:] != B.shape[1:]:
        raise ValueError(f"light field descriptors differ in size: {A.shape[1:]} vs {B.shape[1:]}")
    perm = axis_permutations()                          # (60, 10)
    axis = np.broadcast_to(np.arange(AXES), perm.shape)  # (60, 10)
    symmetric = Y is None
    out = np.empty((A.shape[0], B.shape[0]))
    size = max(1, BLOCK * 25 // A.shape[1] ** 2)  # the memory of a block grows with the light fields squared
    for q in range(A.shape[0]):
        for start in range(q if symmetric else 0, B.shape[0], size):  # a symmetric matrix: its upper triangle
            block = B[start:start + size]
            # L1 of every view of q against every view of the block's shapes: (L, 10, b, L, 10)
            cost = np.abs(A[q][:, :, None, None, None, :] - block[None, None]).sum(axis=-1)
            # rotation r pairs q's axis i with the other's axis perm[r, i]: (60, 10, L, b, L), summed over i
            out[q, start:start + size] = cost[:, axis, :, :, perm].sum(axis=1).min(axis=(0, 1, 3))
    if symmetric:
        upper = np.triu(out)
        out = upper + np.triu(upper, 1).T
    return out


def distance(a, b) -> float:
    """Light field dissimilarity of two descriptors."""
    return float(distance_matrix(a, b)[0, 0])


@stage("light_field", params=LightFieldParams, version=2, consumes=("mesh",), produces=("descriptor",))
def light_field_stage(mesh: Mesh, *, params: LightFieldParams) -> DescriptorResult:
    """The light field descriptor (Chen et al. 2003): Zernike and Fourier features of dodecahedron silhouettes."""
    return DescriptorResult(Descriptor("vector", descriptor(mesh, params)))
