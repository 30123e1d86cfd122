"""The ``jrigid`` command line: ``jrigid list``, ``jrigid run``, ``jrigid demo``, ``jrigid docs``.

Examples::

    jrigid list                          # every experiment, one line each
    jrigid list -v                       # ... with their parameters and defaults
    jrigid run hello --quick             # results in results/hello/
    jrigid run hello n=5 --out /tmp/h    # parameters as key=value (or --param key=value)
    jrigid run all --quick               # every experiment, results/<name>/ each
    jrigid run stability_map --workers 2 # its sweep on a local Dask cluster of 2 processes
    jrigid run stability_map --scheduler tcp://head:8786   # ... on a running cluster
    jrigid demo                          # the wobbling plate and the T-handle
    jrigid docs serve                    # the documentation site at http://127.0.0.1:8000
    jrigid docs build --quick --out site # build it (tutorials at small sizes)

Each run writes figures, ``numbers.json`` and ``report.md`` into its results folder and
prints the report's path. Runs use float64 (``jax_enable_x64``), jrigid's recommended
mode. Unknown experiments, bad parameters (values that do not convert, non-finite numbers
such as ``nan``, ``inf`` or ``1e400``, a negative mass or any parameter the experiment
declares positive, see :mod:`jrigid.registry`) and a results folder that cannot be
written end with exit code 2 and a one-line message on stderr naming the problem, before
anything runs; malformed command lines (unknown options, a missing NAME) also print the
usage.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import traceback
from collections.abc import Sequence
from pathlib import Path

from jrigid import __version__, registry

__all__ = ["build_parser", "main"]

_PARAM_HELP = (
    "experiment parameters as KEY=VALUE, converted to the type of the experiment's default "
    "(bool: true/false; lists: comma-separated); see `jrigid list -v`"
)


def _add_out(parser: argparse.ArgumentParser, help: str) -> None:
    """The ``--out DIR`` option of a subcommand (``None`` when not given)."""
    parser.add_argument("--out", metavar="DIR", type=Path, default=None, help=help)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with its ``list``, ``run``, ``demo``, ``docs`` and ``cache``
    subcommands."""
    parser = argparse.ArgumentParser(
        prog="jrigid",
        description="jrigid: differentiable rigid-body rotation in JAX. "
        "Run experiments and the demo; results go to results/<name>/.",
    )
    parser.add_argument("--version", action="version", version=f"jrigid {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="{list,run,demo,docs,cache}")

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
    p_run.add_argument("name", metavar="NAME", nargs="?",
                       help="experiment name from `jrigid list`, or all")
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
    _add_out(
        p_run, "results folder (default results/NAME; with `all`, the parent of one folder each)"
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
    _add_out(p_demo, "results folder (default results/demo)")
    p_docs = sub.add_parser(
        "docs",
        help="build or serve the documentation site (needs the docs extra)",
        description="Build (mkdocs build --strict) or serve (mkdocs serve) the documentation "
        "site of a source checkout; its tutorials are executed. Needs "
        '`pip install -e ".[docs]"`.',
    )
    p_docs.add_argument("action", choices=("build", "serve"), help="build the site, or serve it")
    p_docs.add_argument("--quick", action="store_true", help="run the tutorials at small sizes")
    _add_out(p_docs, "site folder (default: site/)")
    p_cache = sub.add_parser(
        "cache",
        help="show (or clear) the persistent compilation cache",
        description="Show where jrigid keeps the programs XLA compiled, so that a script run "
        "again loads them instead of compiling them, and how much it holds; `clear` empties "
        "it. JRIGID_CACHE_DIR chooses the directory (off: none).",
    )
    p_cache.add_argument("action", nargs="?", choices=("show", "clear"), default="show",
                         help="show the cache (default) or clear it")
    for p in (p_list, p_run, p_demo, p_docs, p_cache):
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


def _default_out(name: str) -> Path:
    return Path("results") / name


def _unwritable(folder: Path) -> str | None:
    """``None`` if ``folder`` exists or can be created, and a file can be written in it;
    else the reason, in one line. Folders made to find out are removed again (the run
    makes them, unless it refuses its parameters)."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as e:
        return f"cannot write results to {str(folder)!r}: {e.strerror or e}"
    finally:
        for made in missing:  # deepest first
            try:
                made.rmdir()
            except OSError:
                break
    return None


def _run_one(name: str, out: Path | None, quick: bool, params: dict[str, str]) -> Path:
    _enable_float64()
    out = out if out is not None else _default_out(name)
    print(f"== {name}{' (quick)' if quick else ''} -> {out}/", flush=True)
    registry.run(name, out, quick=quick, params=params)
    report = out / "report.md"
    if report.is_file():
        print(f"report: {report}", flush=True)
    else:  # a main that returned no numbers and wrote no summary
        print(f"no report.md: the experiment wrote no summary in {out}/", flush=True)
    return report


def _fail(parser: argparse.ArgumentParser, message: str):
    """Exit with code 2 and ``prog: error: message`` on stderr, one line (no usage)."""
    parser.exit(2, f"{parser.prog}: error: {' '.join(message.split())}\n")


_EXECUTOR_OPTIONS = ("workers", "scheduler")


def _executor_params(p_run: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, str]:
    """``--workers``/``--scheduler`` as the experiment parameters of the same names."""
    out = {}
    workers, scheduler = getattr(args, "workers", None), getattr(args, "scheduler", None)
    if workers is not None:
        if workers < 1:
            _fail(p_run, f"--workers must be at least 1, got {workers}")
        out["workers"] = str(workers)
    if scheduler is not None:
        if not scheduler.strip():
            _fail(p_run, "--scheduler needs an address, e.g. tcp://head:8786")
        out["scheduler"] = scheduler
    if len(out) == 2:
        _fail(p_run, "give --workers (a new local cluster) or --scheduler (a running one), "
              "not both")
    return out


def _cmd_run(p_run: argparse.ArgumentParser, args: argparse.Namespace, name: str) -> int:
    try:
        raw = registry.split_pairs([*args.params, *args.param])
    except registry.ParameterError as e:
        _fail(p_run, str(e))
    clash = [k for k in _EXECUTOR_OPTIONS if k in raw]
    if clash:
        _fail(p_run, f"{clash[0]} is set with --{clash[0]}, not as KEY=VALUE")
    executor = _executor_params(p_run, args)
    if name == "all":
        if raw or executor:
            _fail(p_run, "parameters cannot be given with `run all`; run experiments one by one")
        problem = _unwritable(args.out if args.out is not None else Path("results"))
        if problem:
            _fail(p_run, problem)
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
            _fail(p_run, f"experiment {name!r} does not run on an executor: --workers and "
                  "--scheduler are for experiments with workers/scheduler parameters "
                  "(e.g. stability_map)")
        raw = {**raw, **executor}
        registry.parse_params(name, exp.main, raw)  # check before creating folders
    except (registry.ExperimentError, registry.ParameterError) as e:
        _fail(p_run, str(e))
    problem = _unwritable(args.out if args.out is not None else _default_out(name))
    if problem:
        _fail(p_run, problem)
    try:
        _run_one(name, args.out, args.quick, raw)
    except registry.ParameterError as e:  # a value the parser accepts, the experiment not
        given = ", ".join(f"{k}={v}" for k, v in raw.items()) or "the defaults"
        _fail(p_run, f"experiment {name!r} refused its parameters ({given}): {e}")
    return 0


def docs_command(action: str, quick: bool, out: Path | None) -> tuple[list[str], dict, Path]:
    """The ``mkdocs`` command line, environment and folder of ``jrigid docs ACTION``.

    Raises:
        FileNotFoundError: no ``mkdocs.yml`` next to the ``jrigid`` package (an installed
            copy rather than a source checkout).
    """
    root = Path(__file__).resolve().parent.parent
    config = root / "mkdocs.yml"
    if not config.is_file():
        raise FileNotFoundError(
            f"no mkdocs.yml in {root}: the site is built from a source checkout of jrigid"
        )
    argv = [sys.executable, "-m", "mkdocs", action, "-f", str(config)]
    if action == "build":
        argv.append("--strict")
        if out is not None:
            argv += ["-d", str(out.resolve())]
    env = {**os.environ, "JRIGID_DOCS_QUICK": "1" if quick else "0"}
    return argv, env, root


def _cmd_docs(p_docs: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    try:
        argv, env, root = docs_command(args.action, args.quick, args.out)
    except FileNotFoundError as e:
        p_docs.error(str(e))
    try:
        import mkdocs  # noqa: F401
    except ImportError:
        p_docs.error('mkdocs is not installed: pip install -e ".[docs]"')
    return subprocess.call(argv, env=env, cwd=root)


def _cmd_cache(action: str) -> int:
    from jrigid import _cache

    theirs = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    if theirs:
        print(f"JAX_COMPILATION_CACHE_DIR={theirs} is set: JAX caches there, not in jrigid's")
        return 0
    path = _cache.cache_dir()
    if path is None:
        print(f"the compilation cache is off ({_cache.ENV}={os.environ.get(_cache.ENV, '')!r})")
        return 0
    if os.path.exists(path) and not os.path.isdir(path):
        print(f"{path} is not a directory: nothing is cached (set {_cache.ENV} to a "
              f"directory, or to 'off')")
        return 1
    if os.path.isdir(path) and not os.access(path, os.W_OK | os.X_OK):
        print(f"{path} cannot be written: nothing new is cached (set {_cache.ENV} to "
              f"another directory)")
    if action == "clear":
        removed = _cache.clear(path)
        print(f"{path}: removed {removed} compiled program{'' if removed == 1 else 's'}")
        return 0
    programs, size = _cache.contents(path)
    plural = "" if programs == 1 else "s"
    print(f"{path}: {programs} compiled program{plural}, {size / 2**20:.1f} MiB "
          f"(at most {_cache.MAX_BYTES / 2**20:.0f} MiB; `jrigid cache clear` empties it)")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jrigid`` command.

    Args:
        argv: arguments without the program name; default ``sys.argv[1:]``.

    Returns:
        the exit code (0 success, 1 an experiment failed in ``run all``). Usage errors
        (unknown experiment or parameter, bad or non-finite value, a non-positive value
        for a positive parameter, an unwritable results folder) raise ``SystemExit(2)``
        after printing the problem and the valid choices to stderr in one line.
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
        if args.name is None:
            args.subparser.error("NAME is required: an experiment from `jrigid list`, or all")
        return _cmd_run(args.subparser, args, args.name)
    if args.command == "docs":
        return _cmd_docs(args.subparser, args)
    if args.command == "cache":
        return _cmd_cache(args.action)
    # demo: `jrigid demo ...` is `jrigid run demo ...`
    args.param = []
    return _cmd_run(args.subparser, args, "demo")


if __name__ == "__main__":
    sys.exit(main())
