"""``topomatch match | index | query | evaluate``: shape matching and retrieval from the command line.

Thin layers over :mod:`topomatch.retrieval`. ``--method`` lists the catalogue's methods
(:mod:`topomatch.stages.retrieval.catalogue`) and defaults to its best: the fused method for the
commands on a collection, the best single method for ``match``. The matching options come from
:class:`~topomatch.stages.retrieval.descriptor.MatchOptions`; left out, each method's own apply.
"""

from __future__ import annotations

import argparse
import sys

from topomatch.cli.common import (
    add_executor_options,
    command,
    executor_options,
    input_path,
    path_argument,
    print_json,
    verbosity,
    warn,
)
from topomatch.pipeline.errors import RunError
from topomatch.pipeline.cli_options import Option, add_options, given_options


def _models() -> dict:
    from topomatch.stages.retrieval.descriptor import MatchOptions

    return {"match": MatchOptions}


def _match_options() -> list[Option]:
    from topomatch.stages.retrieval.catalogue import METHODS

    costs = ", ".join(f"{m.name} {m.unmatched_cost:g}" for m in METHODS.values() if m.kind == "endpoints")
    return [Option("match.correspondence", default_help="greedy"),
            Option("match.dissimilarity", default_help="matched"),
            Option("match.unmatched_cost", default_help=f"the method's own: {costs}"),
            Option("match.endpoint_window", default_help="all")]


def _method_arg(p: argparse.ArgumentParser, default: str, *, fusions: bool = True) -> None:
    """``--method``: every method of the catalogue, or (``fusions=False``, for ``match``) the single ones."""
    from topomatch.stages.retrieval.catalogue import METHODS, help_text

    choices = [name for name, m in METHODS.items() if fusions or m.fusion is None]
    left_out = [name for name in METHODS if name not in choices]
    p.add_argument("--method", default=default, choices=choices,
                   help=f"retrieval method (default {default}). {help_text(choices)}" + (
                       f" ({', '.join(left_out)}: fusions, whose scales come from a collection; use index and query)"
                       if left_out else ""))


def _with_match_options(p: argparse.ArgumentParser) -> None:
    add_options(p, _models(), _match_options())


def _given(args: argparse.Namespace) -> dict:
    """The endpoint-matching options given on the command line; a warning when ``args.method`` has no
    endpoint part for them to act on."""
    from topomatch.stages.retrieval.catalogue import get_method

    given = given_options(args, _models(), _match_options()).get("match", {})
    if given and not any(get_method(p).kind == "endpoints" for p in get_method(args.method).parts):
        warn(f"{', '.join('--' + k.replace('_', '-') for k in given)} apply to skeleton-endpoint matching; "
             f"{args.method} has no endpoint part, so they are ignored")
    return given


def add_parsers(sub) -> None:
    command(sub, "match", help="dissimilarity of two meshes", description="Dissimilarity of two meshes by one "
            "retrieval method; for a skeleton method also the endpoint correspondence.", handler=cmd_match,
            build=_match_arguments)
    command(sub, "index", help="index a collection of meshes", description="Compute descriptors of meshes and store "
            "them in a SQLite index; unchanged meshes are skipped.", handler=cmd_index, build=_index_arguments)
    command(sub, "query", help="closest indexed shapes to a mesh", description="Rank the indexed shapes by "
            "dissimilarity to a query mesh.", handler=cmd_query, build=_query_arguments)
    command(sub, "evaluate", help="retrieval metrics of a labelled index", description="Full dissimilarity matrix "
            "of the labelled shapes of an index, PSB metrics (NN, FT, ST, E, DCG, mAP).", handler=cmd_evaluate,
            build=_evaluate_arguments)


def positive_int(text: str) -> int:
    """An argparse type: a whole number of at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _match_arguments(p: argparse.ArgumentParser) -> None:
    from topomatch.stages.retrieval.catalogue import DEFAULT_PAIR_METHOD

    p.add_argument("a", type=input_path, help="first mesh (bundled:NAME for a bundled one)")
    p.add_argument("b", type=input_path, help="second mesh")
    _method_arg(p, DEFAULT_PAIR_METHOD, fusions=False)  # a fusion's scales come from a collection
    _with_match_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _index_arguments(p: argparse.ArgumentParser) -> None:
    from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD

    p.add_argument("paths", nargs="+", type=input_path, help="mesh files or folders (searched recursively); "
                                                             "bundled:meshes for the bundled meshes")
    p.add_argument("--db", type=path_argument, required=True, help="index file (SQLite), created if missing")
    _method_arg(p, DEFAULT_METHOD)
    p.add_argument("--labels", type=input_path, help="CSV with columns relative_path (or path) and class (or label), "
                                                     "paths relative to the CSV's folder")
    add_executor_options(p)
    p.add_argument("--retry-failed", action="store_true", help="recompute meshes recorded as failed")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar (also hidden by -q)")
    p.add_argument("--json", action="store_true", help="print one JSON object: counts per part method, failures")


def _query_arguments(p: argparse.ArgumentParser) -> None:
    from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD

    p.add_argument("mesh", type=input_path, help="query mesh")
    p.add_argument("--db", type=path_argument, required=True, help="index file")
    p.add_argument("-k", type=positive_int, default=10, help="results to show (default 10)")
    _method_arg(p, DEFAULT_METHOD)
    _with_match_options(p)
    p.add_argument("--json", action="store_true", help="print JSON")


def _evaluate_arguments(p: argparse.ArgumentParser) -> None:
    from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD

    p.add_argument("--db", type=path_argument, required=True, help="index file")
    _method_arg(p, DEFAULT_METHOD)
    _with_match_options(p)
    p.add_argument("--out", type=path_argument, help="where to write the matrix (.npz; default next to the index)")
    p.add_argument("--json", action="store_true", help="print JSON")


def cmd_match(args: argparse.Namespace) -> int:
    from topomatch.retrieval import match

    result = match(args.a, args.b, method=args.method, options=_given(args))
    out = result.to_dict()
    if args.json:
        print_json(out)
    else:
        print(f"dissimilarity ({args.method}): {result.dissimilarity:.6g}")
        for mesh, count in ((args.a, result.n_endpoints_a), (args.b, result.n_endpoints_b)):
            if count == 0:
                warn(_no_endpoints(mesh, args.method))
        if result.correspondence is not None:
            print(f"endpoints: {result.n_endpoints_a} vs {result.n_endpoints_b}")
            for pair in result.correspondence:
                print(f"  endpoint {pair['a']:>2} <-> {pair['b']:>2}   Phi = {pair['cost']:.4f}")
    return 0


def cmd_index(args: argparse.Namespace) -> int:
    from topomatch.retrieval import index

    settings = executor_options(args)
    report = index(args.paths, args.db, method=args.method, labels=args.labels, workers=settings.pop("workers", None),
                   executor=settings or None, retry_failed=args.retry_failed,
                   progress=not args.no_progress and verbosity() >= 0)
    if args.json:
        print_json({"db": str(report.db), "method": report.method, "n_files": report.n_files,
                    "seconds": report.seconds, "n_failed": report.failed,
                    "parts": [{"method": p.method, "indexed": p.done, "failed": p.failed,
                               "unchanged": report.n_files - p.todo - p.failed_before, "failed_before": p.failed_before,
                               "seconds": p.seconds, "failures": list(p.failures)} for p in report.parts],
                    "open_meshes": report.open_meshes, "multi_component_meshes": report.multi_component_meshes,
                    "removed": report.removed, "unmatched_labels": report.unmatched_labels})
    else:
        for part in report.parts:
            before = f", {part.failed_before} failed before (skipped; --retry-failed retries them)" \
                if part.failed_before else ""
            print(f"{report.db}: {part.done} indexed, {part.failed} failed, "
                  f"{report.n_files - part.todo - part.failed_before} unchanged (skipped){before} "
                  f"[{part.method}, {part.seconds:.1f} s of worker time]")
        print(f"{report.db}: {report.method} indexed in {report.seconds:.1f} s")
        if report.removed:
            print(f"{report.removed} rows of files no longer in the indexed folders were removed")
        if report.unmatched_labels:
            n = len(report.unmatched_labels)
            warn(f"{args.labels}: {n} labelled {'paths are' if n > 1 else 'path is'} no mesh file of this run "
                 f"(misspelt, missing or not given): {_some(report.unmatched_labels)}")  # not with -q
        if report.open_meshes:
            n = len(report.open_meshes)
            print(f"{n} {'meshes are' if n > 1 else 'mesh is'} open (with boundaries; {_some(report.open_meshes)}): "
                  + _open_meshes_note(report.method))
        if report.multi_component_meshes:
            n = len(report.multi_component_meshes)
            print(f"{n} {'meshes have' if n > 1 else 'mesh has'} several components "
                  f"({_some(report.multi_component_meshes)}): the largest was indexed")
        for part in report.parts:
            for reason in part.failures:
                print(f"  failed ({part.method}): {reason}", file=sys.stderr)
    if report.failed:
        raise RunError(f"{report.failed} descriptors are missing from {report.db} (failed meshes, listed above); "
                       "the others were indexed")
    return 0


def _no_endpoints(mesh: str, method: str) -> str:
    """The warning for a mesh whose skeleton has no endpoints, compared by an endpoint method."""
    return (f"{mesh}: its {method} skeleton has no endpoints (a cycle or a single node after pruning), so its "
            f"{method} dissimilarity only charges the other shape's unmatched endpoints: every shape without "
            "endpoints is at 0 from it; the descriptor methods (hks, shapedna; topomatch on a collection) tell such "
            "shapes apart")


def _some(paths: list[str], shown: int = 3) -> str:
    """The first ``shown`` of ``paths``, then "..." when there are more."""
    return ", ".join(paths[:shown]) + (", ..." if len(paths) > shown else "")


def _open_meshes_note(method: str) -> str:
    """What ``method``'s parts do with a mesh's boundaries."""
    from topomatch.stages.retrieval.catalogue import get_method

    chains = [get_method(p).chain for p in get_method(method).parts]
    if any("fill_holes" in chain for chain in chains):
        return ("their holes were capped (a fan to each boundary loop's centroid) for the spectrum, heat kernel and "
                "skeleton; D2 and spherical harmonics see them as they are")
    stages = {step if isinstance(step, str) else next(iter(step)) for chain in chains for step in chain}
    if stages & {"spectrum", "shapedna", "morse"}:  # a Laplacian on the mesh
        return "the Laplacian and the skeleton use natural (Neumann) boundary conditions"
    return "their surface is sampled as it is"


def cmd_query(args: argparse.Namespace) -> int:
    from topomatch.retrieval import open_index
    from topomatch.stages.retrieval.catalogue import get_method

    result = open_index(args.db).query(args.mesh, k=args.k, method=args.method, options=_given(args))
    if result.n_endpoints == 0 and get_method(args.method).kind == "endpoints":
        warn(_no_endpoints(args.mesh, args.method))
    if args.json:
        print_json(result.to_dict())
    else:
        endpoints = result.n_endpoints if result.n_endpoints is not None else "-"
        shapes = "1 shape" if result.indexed == 1 else f"{result.indexed} shapes"
        print(f"query {args.mesh} ({args.method}, {endpoints} endpoints) against {shapes}:")
        for r in result.results:
            print(f"  {r['rank']:>3}. {r['dissimilarity']:.5f}  {r['label'] or '':<12} {r['path']}")
        if result.fusion is not None:
            print(fusion_line(result.fusion, args.method))
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from topomatch.retrieval import open_index
    from topomatch.stages.retrieval.metrics import PSB_CUTOFF

    ev = open_index(args.db).evaluate(method=args.method, options=_given(args), out=args.out)
    if args.json:
        print_json(ev.to_dict())
    else:
        print(ev.metrics.table(args.method))
        print(f"{ev.n} shapes; matrix ({ev.matrix_seconds:.2f} s) written to {ev.matrix}")
        evaluated = int(ev.metrics.evaluated.sum())
        if evaluated < ev.n:
            print(f"{evaluated} of the {ev.n} shapes are evaluated as queries: the others are in classes of fewer than "
                  f"{PSB_CUTOFF + 1} shapes, which PSB leaves out of the averages (they still count as answers)")
        if ev.fusion is not None:
            print(fusion_line(ev.fusion, args.method))
    return 0


def fusion_line(decision: dict, method: str) -> str:
    """One line saying what the fusion ``method`` did (``decision``: FusionDecision.to_dict())."""
    from topomatch.stages.retrieval.catalogue import get_method
    from topomatch.stages.retrieval.fusion import FusionDecision, scale_factor

    fusion = get_method(method).fusion
    agreement = ", ".join(f"{p} {a:.2f}" for p, a in decision["agreement"].items()) or "not measured"
    against = {"mean": "", "consensus": " with the others' consensus",
               "iterative": " with the kept parts' consensus"}[fusion.agreement_rule]
    dropped = (f"; dropped {', '.join(decision['dropped'])} (agreement{against} below {fusion.screen:g} x the best)"
               if decision["dropped"] else "")
    weights = ""
    if fusion.agreement_power and decision["agreement"]:
        made = FusionDecision.from_dict(decision)
        weights = (f"; weight (agreement / best)^{fusion.agreement_power:g}: "
                   + ", ".join(f"{p} {scale_factor(fusion, made, p):.2f}" for p in decision["kept"]))
    k = decision["rerank_k"] if decision["rerank_k"] is not None else "none"
    normalised = (f", scores / self-scores^{fusion.rerank_normalisation:g}"
                  if fusion.rerank_normalisation and decision["rerank_k"] is not None else "")
    return (f"fusion: kept {', '.join(decision['kept'])}{dropped}; part agreement {agreement}{weights}; "
            f"re-ranking k = {k}{normalised}")
