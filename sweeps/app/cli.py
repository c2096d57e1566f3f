"""The ``shacc`` command line: a thin layer over the library.

Every command and its arguments are declared here, in one place; each command's
code lives in its own module and is imported only when that command runs, so
``shacc precompute`` never imports JAX and every command starts without paying for
the others' libraries (matplotlib, pandas, MuJoCo: about a second together).

Bad input (a scene file, a ``--set``, a path) prints one line naming the file, the
field and the rule, and exits with status 2; a fault of the machine (a full disk, a
read-only folder) one line naming the path and the reason, status 1; Ctrl-C the line
``interrupted``, status 130 (``faults``, ``interrupt``). Nothing is half written.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import warnings
from collections.abc import Sequence

# Nothing heavy here, nor in the parser (NumPy and the rest come with each command's
# module): `shacc sweep` starts its local cluster's fork server before them (_run).
from sweeps import compile_cache


def modes() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The modes a command may be asked for, and the paper's three (the schema's, read
    without importing JAX); `evaluate` runs the paper's three unless asked: the
    optimized mode searches first."""
    from geometry_precompute.schema import ALL_MODES, MODES  # deferred: 35 ms to import

    return ALL_MODES, MODES


def _add_set(p: argparse.ArgumentParser) -> None:
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a setting, e.g. v_max=0.3 or side_grasp.radius_init=0.18 "
                   "(may be repeated; `shacc settings` lists every name with its default, "
                   "type and valid range)")


class _Help(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default, except where there is none to show."""

    def _get_help_string(self, action):
        if action.default in (None, False, [], argparse.SUPPRESS) or action.required:
            return action.help
        return super()._get_help_string(action)


class _Parser(argparse.ArgumentParser):
    """Errors in one line, like every other bad input (docs/reference/errors.md)."""

    def error(self, message: str):
        # argparse's "invalid choice: 'X' (choose from ...)", with the likely one.
        wrong = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if wrong:
            from geometry_precompute.errors import did_you_mean  # deferred: errors only

            choices = re.findall(r"'([^']*)'", wrong.group(2)) or wrong.group(2).split(", ")
            message += did_you_mean(wrong.group(1), choices)
        print(f"error: <arguments>: {self.prog}: {message} (see {self.prog} --help)",
              file=sys.stderr)
        sys.exit(2)

    def _print_message(self, message: str, file=None) -> None:
        # argparse drops a failed write of --help or --version silently (exit 0 with
        # nothing written); a closed or full stdout is the machine's fault here too.
        if message:
            (file or sys.stderr).write(message)


def _int_in(lo: int, hi: int | None = None):
    """An argparse type: an integer within [lo, hi]."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if v < lo or (hi is not None and v > hi):
            rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
            raise argparse.ArgumentTypeError(f"must be an integer {rng}, got {v}")
        return v
    return parse


def _path(text: str) -> str:
    """An argparse type: a path, which is not empty and holds no NUL byte."""
    if not text:
        raise argparse.ArgumentTypeError("must name a file or folder, got an empty string")
    if "\0" in text:
        raise argparse.ArgumentTypeError("a path cannot hold a NUL byte")
    return text


def _version() -> str:
    import importlib.metadata as md  # deferred: 57 ms to import

    try:
        return md.version("shacc")
    except md.PackageNotFoundError:
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="shacc", description="ShaCC batch evaluator. Settings and their "
                "defaults: `shacc settings`.", formatter_class=_Help)
    p.add_argument("--version", action="version", version=f"shacc {_version()}")
    sub = p.add_subparsers(dest="command", required=True)
    MODES, PAPER_MODES = modes()

    def command(name: str, help: str) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=help, formatter_class=_Help)

    c = command("settings", "list every setting: default, type, range, meaning")
    c.add_argument("--json", action="store_true", help="as JSON (one object per setting)")
    c.set_defaults(func="settings_cmd:cmd_settings")

    c = command("templates", "list the skill templates a scene can use, with their "
                "parameters and bounds (docs/reference/templates.md)")
    c.add_argument("scene", nargs="?", type=_path, help="a scene: its template files too, and "
                   "its tasks' bounds for their objects")
    c.add_argument("--file", nargs="+", type=_path, metavar="TEMPLATES.toml",
                   help="template files to list beside the built-in ones")
    c.add_argument("--json", action="store_true", help="as JSON")
    c.set_defaults(func="templates_cmd:cmd_templates")

    c = command("schema", "print the JSON Schema of a scene file, a sweep config or a "
                "template file (for editors; docs/reference/outputs.md)")
    c.add_argument("kind", choices=["scene", "sweep", "templates"])
    c.set_defaults(func="schema_cmd:cmd_schema")

    c = command("precompute", "C, clusters and Shrinking of one scene")
    c.add_argument("scene", type=_path, help="scene TOML file")
    _add_set(c)
    c.add_argument("--json", metavar="OUT.json", type=_path, help="write the one-scene JSON's keys")
    c.set_defaults(func="precompute_cmd:cmd_precompute")

    c = command("evaluate", "evaluate scenes in every mode, as one batch "
                "(docs/reference/outputs.md)")
    c.add_argument("scene", nargs="+", type=_path,
                   help="scene TOML files, or folders of them (all evaluated as one batch)")
    _add_set(c)
    c.add_argument("--modes", nargs="+", default=list(PAPER_MODES), choices=list(MODES),
                   help="modes to evaluate (optimized runs the optimized mode's search first)")
    c.add_argument("--json", metavar="OUT.jsonl", type=_path,
                   help="write the one-scene JSON object (docs/reference/outputs.md), one line per "
                   "scene (JSON Lines)")
    c.add_argument("--plan", action="store_true",
                   help="print how the evaluation would run (pieces of the start grid, "
                   "devices, block sizes, memory) and stop")
    c.set_defaults(func="evaluate_cmd:cmd_evaluate")

    c = command("optimize", "search a scene's best task-space sizes: the optimized mode "
                "(docs/reference/model.md)")
    c.add_argument("scene", type=_path, help="scene TOML file")
    _add_set(c)
    c.add_argument("--json", metavar="OUT.json", type=_path,
                   help="write the one-scene JSON object (docs/reference/outputs.md) with "
                   "modes.optimized and an "
                   "optimize block")
    c.set_defaults(func="optimize_cmd:cmd_optimize")

    c = command("reproduce", "the paper's experiment: Fig. 6 and Fig. 7")
    c.add_argument("--out", default="reproduce_out", type=_path, help="output folder")
    c.add_argument("--random-scenes", type=_int_in(0, 100_000), default=None,
                   help="random scenes (default 20; 4 with --quick)")
    c.add_argument("--seed", type=_int_in(0, 2**31 - 1), default=0,
                   help="seeds the random scenes and bootstrap")
    c.add_argument("--preset", default="paper", choices=["paper", "compact"],
                   help="the random scenes' table area: paper (calibrated to the paper's "
                   "C_init) or compact (0.6 m, the earlier geometry)")
    c.add_argument("--quick", action="store_true",
                   help="few random scenes, a coarse start grid, 200 bootstrap resamples")
    c.add_argument("--field-grid", type=_int_in(2, 1024), default=None,
                   help="start grid per side for Fig. 7 (default 64; 16 with --quick)")
    _add_set(c)
    c.add_argument("--workers", type=_int_in(1, 1024), default=None,
                   help="precompute processes (default: three quarters of the CPUs)")
    c.add_argument("--readme", type=_path, help="also rewrite the marked section of this README")
    c.set_defaults(func="reproduce_cmd:cmd_reproduce")

    c = command("sweep", "a parameter sweep from a TOML config (resumable)")
    c.add_argument("config", type=_path, help="sweep config TOML")
    c.add_argument("--out", type=_path, help="output folder (resumes if it holds this sweep)")
    c.add_argument("--dry-run", action="store_true", help="print sizes and estimates only")
    c.add_argument("--cache", type=_path,
                   help="precompute cache folder (default ~/.cache/shacc/precompute)")
    c.add_argument("--workers", type=_int_in(1, 1024), default=None,
                   help="precompute processes (default: three quarters of the CPUs)")
    c.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on an existing Dask cluster (e.g. tcp://10.0.0.5:8786) instead of "
                   "a local one; overrides the config's scheduler. A refused connection is an "
                   "error at once; a scheduler that does not answer within 10 s, too")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func="sweep_cmd:cmd_sweep")

    c = command("compare", "paired differences of two evaluate outputs or sweep folders of "
                "the same scenes (for CI: --fail-if)")
    c.add_argument("a", type=_path, help="evaluate --json file or sweep folder (before)")
    c.add_argument("b", type=_path, help="the same for after")
    c.add_argument("--fail-if", action="append", default=[], metavar="[MODE.]METRIC:MARGIN",
                   help="a non-inferiority gate: exit with status 3 unless B - A's 95 %% CI "
                   "lies wholly above a negative MARGIN (below a positive one), i.e. B is "
                   "shown no worse than the margin; e.g. shacc.success:-0.02 or "
                   "delta_R_mean:+0.1 (may be repeated)")
    c.add_argument("--fail-if-shown", action="append", default=[],
                   metavar="[MODE.]METRIC:MARGIN",
                   help="the lenient gate: exit with status 3 only if the whole CI lies past "
                   "the margin, i.e. the harm is shown (lets regressions through when "
                   "scenes are few)")
    c.add_argument("--json", metavar="OUT.json", type=_path, help="write the comparison")
    c.add_argument("--bootstrap", type=_int_in(100, 10**6), default=10_000,
                   help="bootstrap resamples of the intervals")
    c.add_argument("--seed", type=_int_in(0, 2**31 - 1), default=0, help="their seed")
    c.set_defaults(func="compare_cmd:cmd_compare")

    c = command("report", "one self-contained HTML page of a sweep folder or an evaluate "
                "--json file (tables with scene-level CIs, figures, provenance)")
    c.add_argument("source", type=_path, help="sweep folder or evaluate --json file")
    c.add_argument("--out", type=_path, help="HTML file (default: report.html in the sweep "
                   "folder, or the JSON file's name with .html)")
    c.set_defaults(func="report_cmd:cmd_report")

    c = command("export-mjcf", "write a scene as MJCF (loads in MuJoCo)")
    c.add_argument("scene", type=_path, help="scene TOML file")
    c.add_argument("out", type=_path, help="MJCF file to write")
    _add_set(c)
    c.set_defaults(func="export_cmd:cmd_export")

    c = command("import-mjcf", "turn a MuJoCo scene's named geoms or bodies into a scene "
                "file (docs/reference/mujoco.md)")
    c.add_argument("xml", type=_path, help="MJCF file")
    c.add_argument("--out", required=True, type=_path, help="scene TOML file to write (mesh "
                   "objects' STL files are written beside it)")
    c.add_argument("--map", type=_path, help="TOML mapping: [[tasks]] id, object (a geom or "
                   "body name), template; optional obstacles = [names], [objects.ID] kind")
    c.add_argument("--task", action="append", default=[], metavar="ID=OBJECT:TEMPLATE",
                   help="a task (may be repeated; added to the mapping's)")
    c.add_argument("--obstacle", action="append", default=[], metavar="NAME",
                   help="a geom or body that becomes an object without a task")
    c.add_argument("--max-tilt", type=float, default=1.0, metavar="DEG",
                   help="level cylinders and boxes tilted less than this, with a warning "
                   "(default 1 degree)")
    c.add_argument("--stand", action="store_true", help="move every object up or down "
                   "until its lowest point is on the table (z = 0): for an object file "
                   "that centres its object on the origin")
    c.set_defaults(func="import_cmd:cmd_import_mjcf")

    c = command("check-collisions", "the gripper collision check of a scene against CPU "
                "MuJoCo, with MJX's pipeline beside it (docs/reference/mujoco.md)")
    c.add_argument("scene", type=_path, help="scene TOML file")
    c.add_argument("--poses", type=_int_in(1, 10**6), default=2000,
                   help="random gripper poses near the scene's objects")
    c.add_argument("--seed", type=_int_in(0, 2**32 - 1), default=0, help="their seed")
    c.add_argument("--json", action="store_true", help="as JSON")
    _add_set(c)
    c.set_defaults(func="check_collisions_cmd:cmd_check_collisions")

    c = command("render", "3-D MuJoCo picture beside the top-down view")
    c.add_argument("scene", type=_path, help="scene TOML file")
    c.add_argument("--out", required=True, type=_path, help="PNG file")
    c.add_argument("--mode", default="shacc", choices=[*PAPER_MODES, "optimized"],
                   help="whose spaces to draw and roll out (optimized runs its search first)")
    c.add_argument("--width", type=_int_in(64, 8192), default=1280,
                   help="picture width in pixels")
    c.add_argument("--height", type=_int_in(64, 8192), default=560,
                   help="picture height in pixels")
    c.add_argument("--path", nargs=2, metavar=("START", "TASK"),
                   help="draw one rollout of --mode and print its outcome: START is a start "
                   "index, TASK a task id (or its index)")
    _add_set(c)
    c.set_defaults(func="render_cmd:cmd_render")
    return p


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """A scene's warnings as one line each on stderr (Python's form adds a source line)."""
    from geometry_precompute.scene import SceneWarning  # deferred: 285 ms to import

    if issubclass(category, SceneWarning):
        print(f"warning: {message}", file=sys.stderr)
    else:
        _default_showwarning(message, category, filename, lineno, file, line)


_default_showwarning = warnings.showwarning


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns its exit status. Every fault ends in one line on
    stderr (``faults.report``): bad input 2, a fault of the machine 1, Ctrl-C 130, a
    bug of ours 70 (``SHACC_DEBUG=1`` shows the traceback of any of them)."""
    # deferred: importing it takes 9 ms
    from sweeps.distributed.faults import GuardedStdout, guard_standard_streams

    guard_standard_streams()
    argv = sys.argv[1:] if argv is None else list(argv)
    from sweeps.output import record_command  # deferred: 312 ms to import

    record_command(argv)
    stdout = sys.stdout
    sys.stdout = GuardedStdout(stdout)
    try:
        return _run(argv)
    except SystemExit as e:  # argparse: --help, --version, bad arguments
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    except BaseException as e:
        from sweeps.distributed.faults import report  # deferred: 9 ms to import

        return report(e)
    finally:
        sys.stdout = stdout


def _run(argv: list[str]) -> int:
    warnings.showwarning = _show_warning
    args = build_parser().parse_args(argv)  # imports neither NumPy nor dask
    if isinstance(getattr(args, "json", None), str):  # --json /dev/stdout is --json -
        from sweeps.output import stdout_alias  # deferred: 312 ms to import

        args.json = stdout_alias(args.json)
    if args.command == "sweep" and not (args.dry_run or args.scheduler):
        # Before this process imports NumPy, dask and the rest: the local cluster's fork
        # server imports the workers' modules meanwhile (a config that names a scheduler
        # leaves the server unused; it ends with this process).
        from sweeps.distributed.cluster import start_fork_server  # deferred: 46 ms to import

        start_fork_server()
    # The sweep's evaluation workers turn the cache on for themselves; its client
    # process never loads JAX.
    if args.command in ("evaluate", "optimize", "reproduce", "render"):
        from shacc_jax import configure_runtime  # deferred: 2.2 s to import

        configure_runtime()  # before anything starts JAX (shacc_jax/runtime.py)
        compile_cache.enable()
    module, name = args.func.split(":")
    func = getattr(importlib.import_module(f"{__package__}.{module}"), name)
    status = func(args)
    from sweeps.distributed.faults import flush_stdout  # deferred: 9 ms to import

    flush_stdout()
    return status
