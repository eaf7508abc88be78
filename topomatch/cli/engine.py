"""``topomatch run | validate | stages | configs``: experiment configs and the stage registry."""

from __future__ import annotations

import argparse
import sys

from topomatch.cli.common import (
    add_executor_options,
    command,
    executor_options,
    info,
    path_argument,
    print_json,
    verbosity,
)
from topomatch.pipeline.errors import RunError
from topomatch.pipeline.paths import DATA_ROOT_ENV


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="experiment config (YAML); an installed one by its name also works "
                                  "(see `topomatch configs`)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value: stage.param=value (noise.sigma=0.01) or a config key "
                        "(executor.kind=dask); repeatable")
    p.add_argument("--data-root", type=path_argument, metavar="DIR", help=f"external data root for {{data_root}} paths "
                                                       f"(default: ${DATA_ROOT_ENV})")
    add_executor_options(p)


def _load(args: argparse.Namespace):
    """The config of ``run`` / ``validate`` with ``--set`` and then the executor options applied."""
    import json

    from topomatch.experiments import load_config

    executor = [f"executor.{key}={json.dumps(value)}" for key, value in executor_options(args).items()]
    return load_config(args.config, overrides=args.overrides + executor, data_root_dir=args.data_root)


def add_parsers(sub) -> None:
    command(sub, "run", help="run an experiment config", description="Run an experiment config and write its run "
            "folder (config, manifest, tables, figures, index.html).", handler=cmd_run, build=_run_arguments)
    command(sub, "validate", help="check a config without running it", description="Validate a config: structure, "
            "stage names, parameters, sweeps, reports, and that the input files exist.", handler=cmd_validate,
            build=_validate_arguments)
    command(sub, "stages", help="list stages and reports with their parameters", description="List every "
            "registered stage and report with parameters and defaults.", handler=cmd_stages,
            build=lambda p: p.add_argument("--json", action="store_true", help="print JSON"))
    command(sub, "configs", help="list the installed experiment configs", description="List the experiment configs "
            "installed with topomatch (run one by its path or name: topomatch run retrieval/demo).",
            handler=cmd_configs, build=lambda p: None)


def _validate_arguments(p: argparse.ArgumentParser) -> None:
    _add_config_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def _run_arguments(p: argparse.ArgumentParser) -> None:
    _add_config_args(p)
    p.add_argument("--out", type=path_argument, metavar="DIR", default="runs", help="parent folder of run folders (default: runs)")
    p.add_argument("--cache-dir", type=path_argument, metavar="DIR", help="stage cache (default: OUT/.cache)")
    p.add_argument("--no-cache", action="store_true", help="recompute everything, store nothing")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar (also hidden by -q)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout: the run folder, counts, "
                                                       "timings, failures and output files")


def cmd_run(args: argparse.Namespace) -> int:
    from topomatch.pipeline.runner import run_experiment

    experiment = _load(args)
    n = len(experiment.items())
    info(f"{experiment.name}: {len(experiment.inputs)} inputs x {len(experiment.sweep_points())} sweep points "
         f"= {n} items, {len(experiment.calls)} stages")
    outcome = run_experiment(
        experiment, out_root=args.out, cache_dir=args.cache_dir, use_cache=not args.no_cache,
        progress=not args.no_progress and verbosity() >= 0,
    )
    m = outcome.manifest
    records = m["outputs"]  # {label: {"files", "notes", "error"}}
    errors = [r["error"] for r in records.values() if r["error"] is not None]
    if args.json:
        print_json({"name": experiment.name, "config": str(experiment.source) if experiment.source else None,
                    "run_dir": str(outcome.run_dir), "index_html": str(outcome.run_dir / "index.html"),
                    "n_items": n, "n_failed": len(outcome.failed), "seconds": m["seconds"],
                    "cache": {"hits": m["cache"]["hits"], "stage_results": m["cache"]["stage_results"]},
                    "failures": [r.error for r in outcome.failed], "report_errors": errors,
                    "outputs": {k: r["files"] for k, r in records.items()},
                    "report_notes": {k: r["notes"] for k, r in records.items() if r["notes"]}})
    else:
        print(f"wrote {outcome.run_dir}/index.html  ({m['seconds']['compute']:.1f} s, "
              f"cache hits {m['cache']['hits']}/{m['cache']['stage_results']})")
        n_files = sum(len(r["files"]) for r in records.values())
        if verbosity() < 1:
            info(f"  {n_files} output files of {len(records)} reports (-v lists them)")
        for label, r in records.items():
            for p in r["files"]:
                info(f"  {label}: {p}", level=1)
            for note in r["notes"]:
                info(f"  {label}: note: {note}", level=1)
    if outcome.failed:
        lines = "\n".join(f"  {r.error}" for r in outcome.failed)
        raise RunError(f"{len(outcome.failed)} of {n} items failed (the others were written):\n{lines}")
    if errors:
        raise RunError("\n".join(errors))
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    experiment = _load(args)
    if args.json:
        print_json({"config": str(experiment.source), "ok": True, "name": experiment.name,
                    "n_inputs": len(experiment.inputs), "n_sweep_points": len(experiment.sweep_points()),
                    "n_items": len(experiment.items()), "stages": [c.label for c in experiment.calls],
                    "reports": [r.name for r in experiment.reports]})
        return 0
    print(f"{experiment.source}: ok ({experiment.name}: {len(experiment.inputs)} inputs, "
          f"{len(experiment.sweep_points())} sweep points, {len(experiment.calls)} stages, "
          f"{len(experiment.reports)} reports)")
    return 0


def cmd_stages(args: argparse.Namespace) -> int:
    from topomatch.pipeline.registry import INPUTS, REPORTS, describe_params, discover, model_in, type_label

    stages = discover()

    def params(model) -> list[dict]:
        return [dict(zip(("name", "type", "default", "description"), row)) for row in describe_params(model)] \
            if model is not None else []

    listing = {
        "stages": {name: {"version": s.version, "consumes": list(s.consumes), "produces": list(s.produces),
                          "doc": s.doc, "params": params(s.params)} for name, s in sorted(stages.items())},
        "reports": {name: {"doc": r.doc, "params": params(r.params)} for name, r in sorted(REPORTS.items())},
        "inputs": {name: {"doc": i.doc, "type": type_label(i.schema), "provides": list(i.provides),
                          "params": params(model_in(i.schema))} for name, i in sorted(INPUTS.items())},
    }
    if args.json:
        print_json(listing, indent=2, default=str)
        return 0
    for kind in ("stages", "reports", "inputs"):
        print(f"{kind.upper()}" + (" (keys under a config's inputs:)" if kind == "inputs" else ""))
        for name, info in listing[kind].items():
            flow = ""
            if kind == "stages":
                flow = f"  (v{info['version']}; {', '.join(info['consumes'])} -> {', '.join(info['produces']) or '-'})"
            elif kind == "inputs":
                flow = f": {info['type']}  (-> {', '.join(info['provides'])})"
            print(f"  {name}{flow}\n      {info['doc']}")
            for p in info["params"]:
                default = "required" if str(p["default"]) == "PydanticUndefined" else f"default {p['default']!r}"
                desc = f"  {p['description']}" if p["description"] else ""
                print(f"      {p['name']}: {p['type']} = {default}{desc}")
        print()
    return 0


def cmd_configs(args: argparse.Namespace) -> int:
    from topomatch.experiments import CONFIGS_DIR, bundled_configs

    for path in bundled_configs():
        print(path.relative_to(CONFIGS_DIR).as_posix())
    print(f"({CONFIGS_DIR})", file=sys.stderr)
    return 0
