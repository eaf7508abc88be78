"""How far the fusion's grid can go on Watertight when it is chosen there: an optimistic bound, not a result.

Usage::

    .venv/bin/python benchmarks/retrieval_watertight_bound.py WT.db

Every setting of the selection protocol's grid (:func:`retrieval_selection.grid_settings`) is
evaluated on all 400 Watertight meshes of an index built with the default method, and the best NN, the
best mAP and the best setting for issue 10's Watertight goal (NN >= 0.96 and mAP >= 0.85 together) are
printed. Choosing on the collection that is reported is what the protocol forbids; this only shows
whether any fusion of the current parts could meet the goal at all.
"""

from __future__ import annotations

import argparse

from retrieval_selection import grid_settings, load, nn_map

from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, get_method
from topomatch.stages.retrieval.fusion import agreement, decide, fused_matrix


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("watertight", help="index of SHREC'07 Watertight (default method, labelled)")
    args = ap.parse_args()
    mats, labels = load(args.watertight)
    base = get_method(DEFAULT_METHOD).fusion
    parts = [mats[p] for p in base.parts]
    agreements = agreement(parts)
    results = [(nn_map(fused_matrix(parts, f, decide(parts, f, agreements=agreements)), labels), name)
               for name, f in grid_settings(base)]
    print(f"{len(results)} settings on {len(labels)} meshes (NN, mAP):")
    print("best NN:", max(results, key=lambda r: (r[0][0], r[0][1])))
    print("best mAP:", max(results, key=lambda r: (r[0][1], r[0][0])))
    print("closest to the goal (min of NN / 0.96 and mAP / 0.85):",
          max(results, key=lambda r: min(r[0][0] / 0.96, r[0][1] / 0.85)))


if __name__ == "__main__":
    main()
