"""``topomatch thesis``: run the thesis's figure and table configs and write one page mapping each
thesis figure and table to our output, the claim, the measured verdict and the config
(:mod:`topomatch.thesis`)."""

from __future__ import annotations

import argparse

from topomatch.cli.common import command, info, path_argument, print_json
from topomatch.pipeline.errors import RunError
from topomatch.pipeline.paths import DATA_ROOT_ENV


def add_parsers(sub) -> None:
    command(sub, "thesis", help="reproduce the thesis's figures and tables on one page",
            description="Run every figure and table config of the thesis (bundled data, and the data root for "
                        "the rest; what is missing is skipped with a note) and write OUT/thesis.html: for each "
                        "thesis figure and table its caption and claim, our figure or table, the measured verdict "
                        "and its reason, the departures from the thesis and the command that re-runs it. With "
                        "--only, the rows asked for replace theirs in the existing page; the others are kept.", handler=cmd_thesis, build=_arguments)


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=path_argument, metavar="DIR", default="thesis",
                   help="folder of the page and of the runs (default: thesis)")
    p.add_argument("--data-root", type=path_argument, metavar="DIR",
                   help=f"external data root (default: ${DATA_ROOT_ENV}); without it the configs that need it are skipped")
    p.add_argument("--only", action="append", default=[], metavar="ID",
                   help="only these figures/tables or configs (repeatable): 'Fig. 3.9', 3.9, 'Table 3.1', "
                        "robustness/noise")
    p.add_argument("--list", action="store_true", help="print the catalogue (every figure and table, its configs, "
                                                       "departures and command) without running anything")
    p.add_argument("--json", action="store_true", help="print one JSON object: the verdict of every item")


def cmd_thesis(args: argparse.Namespace) -> int:
    from topomatch.thesis import catalogue_rows, reproduce

    if args.list:
        rows = catalogue_rows()
        if args.json:
            print_json({"items": rows})
        else:
            width = max(len(r["id"]) for r in rows)
            for r in rows:
                print(f"{r['id']:<{width}}  {', '.join(r['configs']) or '(illustration)':<46}  {r['claim']}")
        return 0
    outcomes = reproduce(args.out, data_root=args.data_root, only=args.only or None, progress=info)
    page = f"{args.out}/thesis.html"
    if args.json:
        print_json({"page": page, "items": [o.to_dict() for o in outcomes]})
    else:
        width = max(len(o.item.id) for o in outcomes)
        for o in outcomes:
            print(f"{o.item.id:<{width}}  {o.verdict:<12}  {o.measured}")
        print(f"wrote {page}")
    missed = [o.item.id for o in outcomes if o.verdict in ("not run", "not measured")]
    if args.only and missed:  # asked for by name: not having run or measured it is a failure, not a skip
        raise RunError(f"{len(missed)} of the {len(outcomes)} items asked for did not run or could not be measured "
                       f"({', '.join(missed)}): their reasons are listed above (the page was written)")
    return 0
