"""The ``jrigid`` command line: ``jrigid list``, ``jrigid run``, ``jrigid demo``.

Examples::

    jrigid list                          # every experiment, one line each
    jrigid list -v                       # ... with their parameters and defaults
    jrigid run hello --quick             # results in results/hello/
    jrigid run hello n=5 --out /tmp/h    # parameters as key=value (or --param key=value)
    jrigid run all --quick               # every experiment, results/<name>/ each
    jrigid run stability_map --workers 2 # its sweep on a local Dask cluster of 2 processes
    jrigid run stability_map --scheduler tcp://head:8786   # ... on a running cluster
    jrigid demo                          # the wobbling plate and the T-handle

Each run writes figures, ``numbers.json`` and ``report.md`` into its results folder and
prints the report's path. Runs use float64 (``jax_enable_x64``), jrigid's recommended
mode. Unknown experiments and bad parameters end with exit code 2 and a message on stderr
naming what is valid.
"""

from __future__ import annotations

import argparse
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path

from jrigid import __version__, registry

__all__ = ["build_parser", "main"]

_PARAM_HELP = (
    "experiment parameters as KEY=VALUE, converted to the type of the experiment's default "
    "(bool: true/false; lists: comma-separated); see `jrigid list -v`"
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with its ``list``, ``run`` and ``demo`` subcommands."""
    parser = argparse.ArgumentParser(
        prog="jrigid",
        description="jrigid: differentiable rigid-body rotation in JAX. "
        "Run experiments and the demo; results go to results/<name>/.",
    )
    parser.add_argument("--version", action="version", version=f"jrigid {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="{list,run,demo}")

    p_list = sub.add_parser(
        "list", help="list every experiment, one line each", description="List every experiment."
    )
    p_list.add_argument(
        "-v", "--verbose", action="store_true", help="also show each experiment's parameters"
    )

    p_run = sub.add_parser(
        "run",
        help="run one experiment (or all)",
        description="Run the experiment NAME (or every experiment with NAME = all) and write "
        "figures, numbers.json and report.md into its results folder.",
    )
    p_run.add_argument("name", metavar="NAME", help="experiment name from `jrigid list`, or all")
    p_run.add_argument("params", nargs="*", metavar="KEY=VALUE", help=_PARAM_HELP)
    p_run.add_argument(
        "-p", "--param", action="append", default=[], metavar="KEY=VALUE", help="same as KEY=VALUE"
    )
    p_run.add_argument("--quick", action="store_true", help="short run with fewer steps and frames")
    p_run.add_argument(
        "--workers",
        metavar="N",
        type=int,
        default=None,
        help="run the experiment's ensemble on a local Dask cluster of N worker processes "
        "(experiments with a `workers` parameter; needs jrigid[distributed])",
    )
    p_run.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="run the experiment's ensemble on the Dask scheduler at ADDRESS "
        "(e.g. tcp://head:8786, a dask-jobqueue cluster)",
    )
    p_run.add_argument(
        "--out",
        metavar="DIR",
        type=Path,
        default=None,
        help="results folder (default results/NAME; with `all`, the parent of one folder each)",
    )

    p_demo = sub.add_parser(
        "demo",
        help="Feynman's wobbling plate and a Dzhanibekov T-handle, with a report",
        description="Simulate Feynman's wobbling plate and a Dzhanibekov T-handle, compare the "
        "measured wobble-to-spin ratio and flip period with theory, and write report.md with "
        "stills and an animation.",
    )
    p_demo.add_argument("params", nargs="*", metavar="KEY=VALUE", help=_PARAM_HELP)
    p_demo.add_argument("--quick", action="store_true", help="shorter run with fewer frames")
    p_demo.add_argument(
        "--out",
        metavar="DIR",
        type=Path,
        default=None,
        help="results folder (default results/demo)",
    )
    for p in (p_list, p_run, p_demo):
        p.set_defaults(subparser=p)  # so that errors print the subcommand's usage
    return parser


def _cmd_list(verbose: bool) -> int:
    found = registry.discover()
    width = max((len(n) for n in found), default=0)
    for name, exp in found.items():
        print(f"{name:<{width}}  {exp.summary}")
        if verbose:
            try:
                print(f"{'':<{width}}    parameters: {registry.describe_parameters(exp.main)}")
            except Exception as e:  # an experiment that fails to import is still listed
                print(f"{'':<{width}}    (cannot import: {type(e).__name__}: {e})")
    if not registry.experiment_dirs():
        print(
            f"(only built-in experiments: no experiments/ folder next to jrigid; "
            f"set {registry.ENV_VAR} to a folder of experiment modules)",
            file=sys.stderr,
        )
    return 0


def _enable_float64() -> None:
    """float64 is jrigid's recommended mode; the command line always runs in it."""
    import jax

    jax.config.update("jax_enable_x64", True)


def _run_one(name: str, out: Path | None, quick: bool, params: dict[str, str]) -> Path:
    _enable_float64()
    out = out if out is not None else Path("results") / name
    print(f"== {name}{' (quick)' if quick else ''} -> {out}/", flush=True)
    registry.run(name, out, quick=quick, params=params)
    report = out / "report.md"
    print(f"report: {report}", flush=True)
    return report


_EXECUTOR_OPTIONS = ("workers", "scheduler")


def _executor_params(p_run: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, str]:
    """``--workers``/``--scheduler`` as the experiment parameters of the same names."""
    out = {}
    workers, scheduler = getattr(args, "workers", None), getattr(args, "scheduler", None)
    if workers is not None:
        if workers < 1:
            p_run.error(f"--workers must be at least 1, got {workers}")
        out["workers"] = str(workers)
    if scheduler is not None:
        if not scheduler.strip():
            p_run.error("--scheduler needs an address, e.g. tcp://head:8786")
        out["scheduler"] = scheduler
    if len(out) == 2:
        p_run.error("give --workers (a new local cluster) or --scheduler (a running one), "
                    "not both")
    return out


def _cmd_run(p_run: argparse.ArgumentParser, args: argparse.Namespace, name: str) -> int:
    try:
        raw = registry.split_pairs([*args.params, *args.param])
    except registry.ParameterError as e:
        p_run.error(str(e))
    clash = [k for k in _EXECUTOR_OPTIONS if k in raw]
    if clash:
        p_run.error(f"{clash[0]} is set with --{clash[0]}, not as KEY=VALUE")
    executor = _executor_params(p_run, args)
    if name == "all":
        if raw or executor:
            p_run.error("parameters cannot be given with `run all`; run experiments one by one")
        failed = []
        for exp_name in registry.discover():
            out = args.out / exp_name if args.out is not None else None
            try:
                _run_one(exp_name, out, args.quick, {})
            except Exception:
                traceback.print_exc()
                failed.append(exp_name)
        if failed:
            print(f"failed: {', '.join(failed)}", file=sys.stderr)
            return 1
        return 0
    try:
        exp = registry.get(name)
        if executor and not set(executor) <= set(registry.parameters(exp.main)[0]):
            p_run.error(f"experiment {name!r} does not run on an executor: --workers and "
                        "--scheduler are for experiments with workers/scheduler parameters "
                        "(e.g. stability_map)")
        raw = {**raw, **executor}
        registry.parse_params(name, exp.main, raw)  # check before creating folders
    except (registry.ExperimentError, registry.ParameterError) as e:
        p_run.error(str(e))
    _run_one(name, args.out, args.quick, raw)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jrigid`` command.

    Args:
        argv: arguments without the program name; default ``sys.argv[1:]``.

    Returns:
        the exit code (0 success, 1 an experiment failed in ``run all``). Usage errors
        (unknown experiment or parameter, bad value) raise ``SystemExit(2)`` after printing
        the valid choices to stderr.
    """
    parser = build_parser()
    # parse_known_args: KEY=VALUE may also follow options (`run NAME --out D a=1`)
    args, extras = parser.parse_known_args(argv)
    if extras:
        sub = getattr(args, "subparser", parser)
        stray = [e for e in extras if e.startswith("-") or "=" not in e]
        if stray or not hasattr(args, "params"):
            sub.error(f"unrecognized arguments: {' '.join(stray or extras)}")
        args.params = [*args.params, *extras]
    if args.command is None:
        parser.print_help()
        return 0
    if args.command == "list":
        return _cmd_list(args.verbose)
    if args.command == "run":
        return _cmd_run(args.subparser, args, args.name)
    # demo: `jrigid demo ...` is `jrigid run demo ...`
    args.param = []
    return _cmd_run(args.subparser, args, "demo")


if __name__ == "__main__":
    sys.exit(main())
