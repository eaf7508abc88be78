"""Real pose collections (issue 29): characters and people in poses made by artists or scanned, not by this project.

Usage::

    # 1. the sources, from public GitHub snapshots (academic use; never copied into the repository)
    .venv/bin/python benchmarks/retrieval_poses.py extract --mirrors /work/.mirror     # -> $TOPOMATCH_POSES/sources
    # 2. the two collections, by the fixed rule below
    .venv/bin/python benchmarks/retrieval_poses.py build                                # -> $TOPOMATCH_POSES/poses_{tune,report}
    # 3. index them (every part of the default) and measure every part, the default and the agreement rules
    .venv/bin/python benchmarks/retrieval_poses.py measure --only poses_tune --json benchmarks/results/retrieval_poses.json
    # 4. after the default was chosen (docs/retrieval.md, "Real poses and the agreement rule"), the report side once
    .venv/bin/python benchmarks/retrieval_poses.py measure --only poses_report --json benchmarks/results/retrieval_poses.json
    .venv/bin/python benchmarks/retrieval_poses.py report --dbs WT.db $TOPOMATCH_POSES/poses_report.db ... \
        --json benchmarks/results/retrieval_poses_report.json

The folder is ``--root``, else ``$TOPOMATCH_POSES``, else ``/tmp/poses``. Nothing is downloaded by the script and
nothing of it belongs in the repository: when the sources or collections are absent, ``build`` and ``measure`` say
so and exit 0 (a clean skip).

Sources (``extract`` reads them from bare git snapshots, ``git show HEAD:path``; the snapshots are fetched by hand,
e.g. with the sessions' ``fetch`` tool, from github.com/<owner>/<name>):

* **TOSCA** (Bronstein, Bronstein, Kimmel, *Numerical geometry of non-rigid shapes*, 2008; academic use), each shape
  remeshed independently to ~5,000 vertices (LRVD) by J. Ren et al., "Continuous and orientation-preserving
  correspondence via functional maps", SIGGRAPH Asia 2018: ``llorz/SGA18_orientation_BCICP_dataset``,
  ``Dataset/TOSCA_Isometric/vtx_5k/*.off`` (cat 11, centaur 6, david 7, dog 9, horse 8, michael 20, victoria 12,
  wolf 3) and ``Dataset/TOSCA_nonIsometric/vtx_5k/*.off`` (gorilla 5, man 7, woman 12);
* **FAUST** registrations (Bogo et al., CVPR 2014; academic use): the same repository, ``Dataset/FAUST/vtx_5k/
  tr_reg_NNN.off`` (100 scans of 10 people in 10 poses, remeshed; person = NNN // 10);
* **SCAPE** (Anguelov et al. 2005, one person in 72 poses; academic use, via the Shape Correspondence Benchmark of
  Kim et al. 2011): ``Batucan2601/Intrinsic-Symmetry-Curve-Generation-``, ``Trilateral/Mesh/SCB/Data/SCAPE/Meshes/
  meshNNN.off``;
* **Sumner and Popovic**'s deformation-transfer poses (SIGGRAPH 2004; academic use), as in
  ``benchmarks/retrieval_sumner.py``: ``mickare/Deformation-Transfer-for-Triangle-Meshes``,
  ``models/highpoly/{cat,lion}-poses.tgz`` (10 each) and ``Golevka/deformation-transfer``, ``bin/horse-*.obj``,
  ``bin/horse_ref.obj`` (11).

**The split rule, fixed before any mesh was indexed or any number read** (2026-12-03): classes are characters
(TOSCA, Sumner) or people (FAUST, SCAPE); a character's poses are all on one side.

1. Within each source the characters are sorted by name; the even-positioned ones (0, 2, ...) go to
   ``poses_tune``, the odd-positioned ones to ``poses_report``: TOSCA (isometric) cat, david, horse, victoria ->
   tune; centaur, dog, michael, wolf -> report. TOSCA (non-isometric) gorilla, woman -> tune; man -> report.
   FAUST people 0-5 only (to keep each collection near 100 meshes): 0, 2, 4 -> tune; 1, 3, 5 -> report.
   SCAPE (one person) -> tune, its poses 0, 7, 14, ..., 63 (10 of the 72).
2. Sumner's cat, lion and horse go to ``poses_report`` only: they already form the report collections ``sumner`` /
   ``sumner_open`` (docs/retrieval.md), so they may not be chosen on.
3. Every mesh is read as it is (each source is ~5,000-12,000 vertices except Sumner's, which the index decimates like
   any other mesh) and gets 1-3 holes with probability 0.5 (:func:`retrieval_collections.write_member`; seed 21 for
   tune, 22 for report), so about half are open.

``poses_tune``: 10 classes, 95 meshes (cat 11, david 7, horse 8, victoria 12, gorilla 5, woman 12, faust0, faust2,
faust4 10 each, scape 10). ``poses_report``: 11 classes, 106 meshes (centaur 6, dog 9, michael 20, wolf 3, man 7,
faust1, faust3, faust5 10 each, sumner_cat 10, sumner_lion 10, sumner_horse 11). Both hold similar characters side
by side (people; cats and dogs), as issue 10's hidden collection does (TOSCA's David and Michael). Note: the hidden
collection is TOSCA-like, so some of its characters may be in ``poses_tune``: the tune side has seen real poses of
them, which is the point of a real tune collection, and a reason to read ``poses_report`` (its other characters) as
the check.

``measure`` indexes both collections with the default method (every part) through the public API
(:func:`topomatch.retrieval.index`), evaluates every part alone and the default fusion with the project's evaluator
(:meth:`topomatch.retrieval.Collection.evaluate`), and adds each agreement rule of :class:`Fusion` on the same part
matrices.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from retrieval_collections import write_member  # noqa: E402

BCICP = "llorz+SGA18_orientation_BCICP_dataset"
SCB = "Batucan2601+Intrinsic-Symmetry-Curve-Generation-"
MICKARE = "mickare+Deformation-Transfer-for-Triangle-Meshes"
GOLEVKA = "Golevka+deformation-transfer"

TOSCA_ISO = ["cat", "centaur", "david", "dog", "horse", "michael", "victoria", "wolf"]
TOSCA_NONISO = ["gorilla", "man", "woman"]
FAUST_PEOPLE = range(6)
SCAPE_POSES = range(0, 70, 7)
SUMNER = ["cat", "horse", "lion"]
SEEDS = {"poses_tune": 21, "poses_report": 22}
OPEN_FRACTION = 0.5


def root_folder(given: str | None) -> Path:
    return Path(given or os.environ.get("TOPOMATCH_POSES") or "/tmp/poses")


def _git(gitdir: Path, *args: str) -> bytes:
    return subprocess.run(["git", "--git-dir", str(gitdir), *args], check=True, capture_output=True).stdout


def _files(gitdir: Path, folder: str) -> list[str]:
    return _git(gitdir, "ls-tree", "-r", "--name-only", "HEAD", folder).decode().split()


def extract(mirrors: Path, out: Path) -> dict[str, int]:
    """The source meshes, from the bare git snapshots under ``mirrors`` (``owner+name/repo``), into ``out``."""
    counts = {}

    def save(sub: str, name: str, data: bytes) -> None:
        (out / sub).mkdir(parents=True, exist_ok=True)
        (out / sub / name).write_bytes(data)
        counts[sub] = counts.get(sub, 0) + 1

    repo = mirrors / BCICP / "repo"
    for sub, folder in (("tosca", "Dataset/TOSCA_Isometric/vtx_5k/"), ("tosca", "Dataset/TOSCA_nonIsometric/vtx_5k/"),
                        ("faust", "Dataset/FAUST/vtx_5k/")):
        for f in _files(repo, folder):
            if f.endswith(".off") and f.count("/") == 3:
                save(sub, Path(f).name, _git(repo, "show", f"HEAD:{f}"))
    repo = mirrors / SCB / "repo"
    for i in SCAPE_POSES:
        f = f"Trilateral/Mesh/SCB/Data/SCAPE/Meshes/mesh{i:03d}.off"
        save("scape", Path(f).name, _git(repo, "show", f"HEAD:{f}"))
    repo = mirrors / MICKARE / "repo"
    for animal in ("cat", "lion"):
        with tarfile.open(fileobj=io.BytesIO(_git(repo, "show", f"HEAD:models/highpoly/{animal}-poses.tgz"))) as tar:
            for member in tar.getmembers():
                if member.isfile() and member.name.endswith(".obj"):
                    save("sumner", Path(member.name).name, tar.extractfile(member).read())
    repo = mirrors / GOLEVKA / "repo"
    for f in _files(repo, "bin/"):
        if Path(f).name.startswith("horse") and f.endswith(".obj"):
            save("sumner", Path(f).name, _git(repo, "show", f"HEAD:{f}"))
    return counts


def _tosca_character(stem: str) -> str:
    """cat10 -> cat; 8_gorilla_01 -> gorilla."""
    return stem.split("_")[1] if stem.startswith("8_") else stem.rstrip("0123456789")


def members(sources: Path) -> dict[str, list[tuple[Path, str]]]:
    """{collection: [(mesh file, class)]} by the split rule of the module docstring."""
    out = {"poses_tune": [], "poses_report": []}
    sides = ("poses_tune", "poses_report")
    for names in (TOSCA_ISO, TOSCA_NONISO):
        for pos, character in enumerate(sorted(names)):
            files = sorted(p for p in (sources / "tosca").glob("*.off") if _tosca_character(p.stem) == character)
            out[sides[pos % 2]] += [(p, character) for p in files]
    for person in FAUST_PEOPLE:
        files = [sources / "faust" / f"tr_reg_{10 * person + i:03d}.off" for i in range(10)]
        out[sides[person % 2]] += [(p, f"faust{person}") for p in files]
    out["poses_tune"] += [(sources / "scape" / f"mesh{i:03d}.off", "scape") for i in SCAPE_POSES]
    for animal in SUMNER:
        files = sorted(p for p in (sources / "sumner").glob("*.obj") if p.name.split("-")[0].split("_")[0] == animal)
        out["poses_report"] += [(p, f"sumner_{animal}") for p in files]
    return out


def build(sources: Path, root: Path) -> dict[str, int]:
    import topomatch

    built = {}
    for name, files in members(sources).items():
        missing = [str(p) for p, _ in files if not p.exists()]
        if missing:
            raise SystemExit(f"{sources}: {len(missing)} source meshes missing (e.g. {missing[0]}); run extract first")
        folder = root / name
        folder.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng(SEEDS[name])
        rows = ["relative_path,class"]
        for path, cls in files:
            mesh = topomatch.read_mesh(path)
            V, F = np.asarray(mesh.V, float), np.asarray(mesh.F, np.int64)
            rows.append(write_member(folder, f"{cls}_{path.stem}", cls, V, F, rng, OPEN_FRACTION))
        (folder / "labels.csv").write_text("\n".join(rows) + "\n")
        built[name] = len(rows) - 1
    return built


#: Methods measured alone on each collection besides the default's parts (the catalogue's other single methods
#: that need no skeleton of the thesis; ``--thesis`` adds rgpd and srg).
EXTRA_METHODS = ("sdgdm", "shapedna-full")


def measure(root: Path, args) -> None:
    """Index both collections and write every method's NN / mAP (the project's evaluator) and the agreement rules'."""
    from dataclasses import replace

    from retrieval_selection import load, nn_map

    from topomatch.retrieval import index, open_index
    from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, FUSION_PARTS, get_method
    from topomatch.stages.retrieval.fusion import decide, fused_matrix

    names = [n for n in args.only or ("poses_tune", "poses_report") if (root / n / "labels.csv").is_file()]
    if not names:
        print(f"{root}: no pose collections (academic-use data, not bundled): run extract and build first -- skipped")
        return
    extra = EXTRA_METHODS + (("rgpd", "srg") if args.thesis else ())
    out = {"root": str(root), "collections": {}}
    base = get_method(DEFAULT_METHOD).fusion
    for name in names:
        folder, db = root / name, root / f"{name}.db"
        timings = {}
        for method in (DEFAULT_METHOD,) + extra:
            report = index([folder], db, method=method, labels=folder / "labels.csv", workers=args.workers)
            timings[method] = round(report.seconds, 1)
            if report.failed:
                print(f"{name}: {report.failed} meshes failed for {method}")
        collection = open_index(db)
        rows = {}
        for method in FUSION_PARTS + extra + ("topomatch-equal", DEFAULT_METHOD):
            ev = collection.evaluate(method=method)
            rows[method] = {"nn": round(float(ev.metrics.micro["nn"]), 4), "map": round(float(ev.metrics.micro["map"]), 4)}
            if ev.fusion:
                rows[method]["decision"] = ev.fusion
        mats, labels = load(str(db))
        part_list = [mats[p] for p in base.parts]
        rules = {}
        for rule in ("mean", "consensus", "iterative"):
            for screen in (0.5, 0.6, 0.65, 0.7, 0.8, 0.9):
                fusion = replace(base, agreement_rule=rule, screen=screen)
                decision = decide(part_list, fusion)
                nn, ap = nn_map(fused_matrix(part_list, fusion, decision), labels)
                rules[f"{rule} {screen:g}"] = {"nn": round(nn, 4), "map": round(ap, 4), "kept": list(decision.kept),
                                               "agreement": {p: round(a, 3) for p, a in decision.agreement.items()}}
        out["collections"][name] = {"n": int(len(labels)), "classes": int(len(set(labels))), "methods": rows,
                                    "agreement_rules": rules, "index_seconds": timings}
        print(f"\n{name} ({len(labels)} meshes, {len(set(labels))} classes)")
        for method, r in rows.items():
            print(f"  {method:16s} {r['nn']:.3f} / {r['map']:.3f}" + (f"  kept {r['decision']['kept']}" if "decision" in r else ""))
        for setting, r in rules.items():
            print(f"  {setting:16s} {r['nn']:.3f} / {r['map']:.3f}  kept {r['kept']}")
    if args.json:
        path = Path(args.json)
        if path.is_file():  # measured one collection at a time (tune first): keep the others
            before = json.loads(path.read_text())
            out["collections"] = {**before.get("collections", {}), **out["collections"]}
        path.write_text(json.dumps(out, indent=1) + "\n")


#: Fusion variants shown beside the default on the report side (issue 29): the default before (the mean rule, screen
#: 0.5), the protocol's pick without the guard, and the new rules at the screens the guarded protocol tied.
REPORT_VARIANTS = {"default before (mean, screen 0.5)": ("mean", 0.5), "mean, screen 0.9": ("mean", 0.9),
                   "consensus, screen 0.65": ("consensus", 0.65), "iterative, screen 0.65": ("iterative", 0.65),
                   "iterative, screen 0.8": ("iterative", 0.8)}


def report(dbs: list[str], json_path: str | None) -> None:
    """Every part, topomatch-equal, the default and :data:`REPORT_VARIANTS` on each index (NN / mAP, micro), and the
    default's best part; written once, after the default was chosen."""
    from dataclasses import replace

    from retrieval_selection import load, nn_map

    from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, get_method
    from topomatch.stages.retrieval.fusion import decide, fused_matrix

    base = get_method(DEFAULT_METHOD).fusion
    equal = get_method("topomatch-equal").fusion
    out = {"default": repr(base), "collections": {}}
    for db in dbs:
        mats, labels = load(db)
        parts = [mats[p] for p in base.parts]
        rows = {p: nn_map(mats[p], labels) for p in base.parts}
        rows["topomatch-equal"] = nn_map(fused_matrix(parts, equal), labels)
        decision = decide(parts, base)
        rows["topomatch (default)"] = nn_map(fused_matrix(parts, base, decision), labels)
        kept = {"topomatch (default)": list(decision.kept)}
        for name, (rule, screen) in REPORT_VARIANTS.items():
            fusion = replace(base, agreement_rule=rule, screen=screen)
            d = decide(parts, fusion)
            rows[name] = nn_map(fused_matrix(parts, fusion, d), labels)
            kept[name] = list(d.kept)
        best_nn = max(base.parts, key=lambda p: rows[p][0])
        best_map = max(base.parts, key=lambda p: rows[p][1])
        name = Path(db).name.removesuffix(".db")
        out["collections"][name] = {"n": int(len(labels)), "methods": {m: [round(x, 4) for x in r] for m, r in rows.items()},
                                    "kept": kept, "best_part": {"nn": [best_nn, rows[best_nn][0]],
                                                                "map": [best_map, rows[best_map][1]]}}
        print(f"\n{name} ({len(labels)}): best part NN {best_nn} {rows[best_nn][0]:.3f}, mAP {best_map} "
              f"{rows[best_map][1]:.3f}")
        for m, (nn, ap) in rows.items():
            print(f"  {m:36s} {nn:.3f} / {ap:.3f}" + (f"  kept {kept[m]}" if m in kept else ""))
    if json_path:
        Path(json_path).write_text(json.dumps(out, indent=1) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("command", choices=["extract", "build", "measure", "report"])
    ap.add_argument("--root", help="folder of the sources and collections (default $TOPOMATCH_POSES or /tmp/poses)")
    ap.add_argument("--mirrors", type=Path, default=Path("/work/.mirror"), help="extract: the bare git snapshots")
    ap.add_argument("--json", help="measure, report: write the results here")
    ap.add_argument("--dbs", nargs="*", default=[], help="report: indexes of the default method (labelled)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", nargs="*", help="measure: only these collections (poses_tune, poses_report)")
    ap.add_argument("--thesis", action="store_true", help="measure: also the thesis's skeleton methods (rgpd, srg)")
    args = ap.parse_args()
    root = root_folder(args.root)
    if args.command == "extract":
        print(extract(args.mirrors, root / "sources"))
    elif args.command == "build":
        if not (root / "sources").is_dir():
            print(f"{root / 'sources'}: no pose sources (academic-use data, not bundled); run extract first -- skipped")
            return
        print(build(root / "sources", root))
    elif args.command == "report":
        report(args.dbs, args.json)
    else:
        measure(root, args)


if __name__ == "__main__":
    main()
