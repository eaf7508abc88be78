"""How far the fusion's grid can go on Watertight when it is chosen there: an optimistic bound, not a result.

Usage::

    .venv/bin/python benchmarks/retrieval_watertight_bound.py WT.db [--depth-buffer] [--k-reciprocal] [--parts gps,lfd]

Every setting of the selection protocol's grid (:func:`retrieval_selection.grid_settings`) is
evaluated on all 400 Watertight meshes of an index built with the default method, and the best NN, the
best mAP and the best setting for issue 10's Watertight goal (NN >= 0.96 and mAP >= 0.85 together) are
printed. Choosing on the collection that is reported is what the protocol forbids; this only shows
whether any fusion of the current parts could meet the goal at all.

Two ways past the current parts, tried here (2026-12-02, fourth session) before concluding that the goal is
out of reach; neither is part of the product:

* ``--depth-buffer`` adds a sixth part, the depth-buffer descriptor of Vranic's DESIRE (the strongest of
  the classic rigid, view-based global descriptors that needs no training): the mesh in its area-weighted
  principal frame (axes by decreasing variance, each signed by its third moment), six orthographic depth
  images (64 x 64, one per face of the bounding cube, rays cast with Open3D's ``RaycastingScene``), and the
  magnitudes of their 2-D Fourier coefficients with ``|u| + |v| <= 8`` (73 per image, 438 in all),
  compared by L1. D. V. Vranic, "3D Model Retrieval", PhD thesis, Universitaet Leipzig, 2004, sec. 4.
* ``--k-reciprocal`` re-ranks the unre-ranked fused matrix by k-reciprocal encoding (Jaccard distance of
  the expanded k-reciprocal neighbour sets mixed with the original; Zhong et al., CVPR 2017) instead of
  manifold ranking, over k1 in (10, 20, 30), k2 in (1, 6), lambda in (0.1, 0.3).

``--parts gps,lfd`` (issue 29, 2026-12-05, third session) adds issue 29's new parts, the global point signature
distance histograms and the light field descriptor, as further parts of the fusion (the index must hold their rows:
``topomatch index ... --method gps``, ``--method lfd``), to ask the same question of seven parts.
"""

from __future__ import annotations

import argparse
import itertools
from dataclasses import replace

import numpy as np
from retrieval_selection import ORDER_WEIGHTS, grid_settings, load, nn_map

from topomatch.meshes import read_mesh
from topomatch.retrieval import open_index
from topomatch.stages.retrieval.baselines.sampling import area_centroid_and_rms_radius, triangle_areas
from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, get_method
from topomatch.stages.retrieval.fusion import agreement, decide, fused_matrix

#: Depth image side and the Fourier coefficients kept (|u| + |v| <= DEPTH_FREQUENCIES), after Vranic (2004).
DEPTH_IMAGE = 64
DEPTH_FREQUENCIES = 8


def principal_frame(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(n, 3) vertices in the surface's area-weighted principal frame (exact triangle second moments; axes by
    decreasing variance, each flipped so that the area-weighted third moment of the face centroids is >= 0)."""
    area = triangle_areas(V, F)
    centroid = area_centroid_and_rms_radius(V, F, area)[0]
    T = V[F] - centroid
    s = T.sum(axis=1)
    C = (np.einsum("f,fi,fj->ij", area, s, s) + np.einsum("f,fki,fkj->ij", area, T, T)) / (12.0 * area.sum())
    axes = np.linalg.eigh(C)[1][:, ::-1]
    X = (V - centroid) @ axes
    third = (area[:, None] * X[F].mean(axis=1) ** 3).sum(axis=0)
    return X * np.where(third < 0, -1.0, 1.0)


def depth_buffer_descriptor(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(6 * 73,) Fourier magnitudes of the six depth images of the mesh (V (n, 3), F (m, 3)) in its principal frame."""
    import open3d as o3d

    X = principal_frame(np.asarray(V, float), np.asarray(F))
    half = float(np.abs(X).max()) * 1.0001
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(X.astype(np.float32)), o3d.core.Tensor(np.asarray(F, np.uint32)))
    g = ((np.arange(DEPTH_IMAGE) + 0.5) / DEPTH_IMAGE * 2.0 - 1.0) * half
    gu, gv = np.meshgrid(g, g, indexing="ij")
    rays = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for sign in (1.0, -1.0):
            ray = np.zeros((DEPTH_IMAGE, DEPTH_IMAGE, 6))
            ray[..., u], ray[..., v], ray[..., axis], ray[..., 3 + axis] = gu, gv, sign * 1.01 * half, -sign
            rays.append(ray)
    hit = scene.cast_rays(o3d.core.Tensor(np.stack(rays).reshape(-1, 6).astype(np.float32)))["t_hit"].numpy()
    t = hit.reshape(6, DEPTH_IMAGE, DEPTH_IMAGE)
    depth = np.where(np.isfinite(t), 1.0 - (t - 0.01 * half) / (2.0 * half), 0.0)
    K = DEPTH_FREQUENCIES
    uv = np.array([(a, b) for b in range(K + 1) for a in range(-(K - b), K - b + 1) if b > 0 or a >= 0])
    return np.abs(np.fft.fft2(depth)[:, uv[:, 0] % DEPTH_IMAGE, uv[:, 1]]).ravel() / DEPTH_IMAGE ** 2


def k_reciprocal(D: np.ndarray, k1: int, k2: int, lam: float) -> np.ndarray:
    """(n, n) k-reciprocal re-ranking of the dissimilarities D (n, n) (Zhong et al. 2017, without the query/gallery
    split). D is used as it is, divided by its maximum (the paper squares Euclidean feature distances and
    normalises per column; a fused dissimilarity is neither)."""
    n = len(D)
    D = D / D.max()
    order = np.argsort(D, axis=1, kind="stable")

    def reciprocal(i: int, k: int) -> np.ndarray:
        near = order[i, :k + 1]
        return near[np.any(order[near, :k + 1] == i, axis=1)]

    W = np.zeros((n, n))
    for i in range(n):
        R = reciprocal(i, k1)
        expanded = [R] + [Rc for c in R for Rc in [reciprocal(c, int(round(k1 / 2)))]
                          if len(np.intersect1d(Rc, R)) > 2 / 3 * len(Rc)]
        R = np.unique(np.concatenate(expanded))
        w = np.exp(-D[i, R])
        W[i, R] = w / w.sum()
    if k2 > 1:
        W = W[order[:, :k2]].mean(axis=1)
    shared = np.stack([np.minimum(W[i], W).sum(axis=1) for i in range(n)])  # row by row: (n, n), not (n, n, n)
    return (1.0 - lam) * (1.0 - shared / (2.0 - shared)) + lam * D


def report(results: list[tuple[tuple[float, float], str]], what: str) -> None:
    print(f"{what}: {len(results)} settings (NN, mAP)")
    print("  best NN:", max(results, key=lambda r: (r[0][0], r[0][1])))
    print("  best mAP:", max(results, key=lambda r: (r[0][1], r[0][0])))
    print("  closest to the goal (min of NN / 0.96 and mAP / 0.85):",
          max(results, key=lambda r: min(r[0][0] / 0.96, r[0][1] / 0.85)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("watertight", help="index of SHREC'07 Watertight (default method, labelled)")
    ap.add_argument("--depth-buffer", action="store_true", help="add the depth-buffer descriptor as a sixth part")
    ap.add_argument("--k-reciprocal", action="store_true", help="also re-rank by k-reciprocal encoding")
    ap.add_argument("--parts", default="", help="vector methods added as parts (comma-separated: gps, lfd)")
    args = ap.parse_args()
    extra = tuple(p for p in args.parts.split(",") if p)
    mats, labels = load(args.watertight, extra)
    base = get_method(DEFAULT_METHOD).fusion
    base = replace(base, parts=base.parts + extra)
    parts = [mats[p] for p in base.parts]
    for p in extra:
        print(f"{p} alone (NN, mAP):", nn_map(mats[p], labels))
    if args.depth_buffer:
        rows, _ = open_index(args.watertight).parts(DEFAULT_METHOD)
        X = np.stack([depth_buffer_descriptor(m.V, m.F) for m in (read_mesh(r.path) for r in rows if r.label)])
        parts.append(np.abs(X[:, None, :] - X[None, :, :]).sum(axis=2))
        base = replace(base, parts=base.parts + ("depth-buffer",))
        print("depth buffer alone (NN, mAP):", nn_map(parts[-1], labels))
        print("default fusion with it:", nn_map(fused_matrix(parts, base), labels))
    agreements = agreement(parts)
    report([(nn_map(fused_matrix(parts, f, decide(parts, f, agreements=agreements)), labels), name)
            for name, f in grid_settings(base)], f"grid on {len(labels)} meshes, parts {', '.join(base.parts)}")
    if args.k_reciprocal:
        results = []
        for w, ow in ORDER_WEIGHTS.items():
            fused = fused_matrix(parts, replace(base, order_weights=ow, screen=None, rerank_k=None))
            for k1, k2, lam in itertools.product((10, 20, 30), (1, 6), (0.1, 0.3)):
                results.append((nn_map(k_reciprocal(fused, k1, k2, lam), labels),
                                f"weights {w}; k-reciprocal k1 {k1}, k2 {k2}, lambda {lam}"))
        report(results, "k-reciprocal re-ranking of the unscreened fusion")


if __name__ == "__main__":
    main()
