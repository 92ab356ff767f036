"""The ``rve`` command line.

    rve run CONFIG [--set KEY=VALUE ...] [--out DIR] [-v]   run a scene, write DIR/summary.json
                                                             (a pipeline scene: print its snakemake command)
    rve validate CONFIG [--set KEY=VALUE ...] [--json]       print the resolved config (internal units)
    rve schema SCENE                                         print the JSON schema of a scene's input
    rve scenes                                               list the known scenes
    rve table summary|interpolate|export|plot PATH ...       work with an RVE lookup table
    rve check PATH... [--quarantine] [--no-residual]          verify states, tables (checksums, equilibrium)
                                                             and configs (validation + pre-flight checks)

Every scene name comes from the one registry, ``rve.scenes.registry``. Exit codes: 0
success (also ``rve run`` of a pipeline scene, which prints the command that builds it),
1 the scene failed (``SceneFailure``: one message, the last good state saved under
DIR), 2 invalid configuration or usage, also a pipeline config given where a scene config
is expected (messages on stderr, no traceback); docs/configuration.md. A new subcommand is a function ``_add_<name>(subparsers)`` that adds its
parser with ``set_defaults(func=...)``, listed in ``_SUBCOMMANDS``.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Optional, Sequence

from .config import ConfigError, NotASceneConfig, config_as_dict, config_units, json_schema, load_config
from .io.atomic import atomic_write_json
from .io.provenance import package_version, to_jsonable
from .scenes.protocol import SceneFailure
from .scenes.registry import SCENES, get_scene, run_scene

__all__ = ["main", "build_parser", "format_config"]

log = logging.getLogger("rve.cli")

EXIT_OK = 0
EXIT_SCENE_FAILED = 1
EXIT_CONFIG = 2


def _setup_logging(verbosity: int) -> None:
    level = logging.WARNING if verbosity <= 0 else logging.INFO if verbosity == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    # basicConfig does nothing when the root logger already has handlers (pytest, notebooks);
    # the package loggers ("rve", "rve.newton", ...) get the level either way.
    logging.getLogger("rve").setLevel(level)


def _config_error(exc: ConfigError, source: Optional[str] = None) -> int:
    if isinstance(exc, NotASceneConfig):
        print(f"rve: {source or 'config'}: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    head = f"rve: invalid configuration{f' {source}' if source else ''}:"
    print(head, file=sys.stderr)
    for line in exc.errors:
        print(f"  {line}", file=sys.stderr)
    return EXIT_CONFIG


# --------------------------------------------------------------------------- formatting
def _yaml_scalar(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    return json.dumps(value)


def format_config(cfg) -> str:
    """The validated config as YAML in internal units, each quantity annotated with its
    unit (``radius: 0.02  # mm``). The output is itself a valid config."""
    data = config_as_dict(cfg)
    units = config_units(cfg)
    lines: list[str] = []

    def emit(d: dict, u: dict, indent: int) -> None:
        pad = "  " * indent
        for key, value in d.items():
            unit = u.get(key) if isinstance(u, dict) else None
            if isinstance(value, dict):
                lines.append(f"{pad}{key}:")
                emit(value, unit if isinstance(unit, dict) else {}, indent + 1)
            else:
                text = f"{pad}{key}: {_yaml_scalar(value)}"
                if isinstance(unit, str) and unit != "dimensionless":
                    text += f"  # {unit}"
                lines.append(text)

    emit(data, units, 0)
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- subcommands
def _cmd_run(args: argparse.Namespace) -> int:
    try:
        cfg = load_config(args.config, args.overrides)
    except ConfigError as exc:
        return _config_error(exc, args.config)
    scene = get_scene(cfg.scene)
    if scene.kind == "pipeline":
        print(f"rve: {args.config}: scene {scene.name!r} is a pipeline scene (Snakemake jobs, not run in-process); "
              f"build it with:", file=sys.stderr)
        print(scene.module.snakemake_command(args.config, args.overrides))
        return EXIT_OK
    out_dir = Path(args.out) if args.out else Path("results") / "runs" / Path(args.config).stem
    from .io.atomic import unwritable_reason   # before the run: an unwritable folder is found now, not at its end

    if unwritable_reason(out_dir):
        print(f"rve: output folder {out_dir}: cannot be written ({unwritable_reason(out_dir)})", file=sys.stderr)
        return EXIT_CONFIG
    log.info("running scene %s -> %s", cfg.scene, out_dir)
    try:
        summary = run_scene(cfg, out_dir)
    except SceneFailure as failure:
        print(f"rve: {failure}", file=sys.stderr)
        return EXIT_SCENE_FAILED
    resolved = config_as_dict(cfg)
    record = dict(summary)
    record.setdefault("provenance", {
        "scene": cfg.scene,
        "config_file": str(args.config),
        "overrides": list(args.overrides),
        "config": resolved,
        "rve_version": package_version(),
        "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    })
    atomic_write_json(out_dir / "config.json", resolved)
    path = atomic_write_json(out_dir / "summary.json", record)
    print(json.dumps(to_jsonable(summary), indent=2))
    print(f"rve: wrote {path}", file=sys.stderr)
    return EXIT_OK


def _cmd_validate(args: argparse.Namespace) -> int:
    try:
        cfg = load_config(args.config, args.overrides)
    except ConfigError as exc:
        return _config_error(exc, args.config)
    if args.json:
        print(json.dumps(config_as_dict(cfg), indent=2))
    else:
        print(f"# {args.config}: valid; resolved values in internal units (mm, ms, g, N, MPa, K, A, V, kT)")
        sys.stdout.write(format_config(cfg))
    return EXIT_OK


def _cmd_schema(args: argparse.Namespace) -> int:
    try:
        schema = json_schema(args.scene)
    except ConfigError as exc:
        return _config_error(exc)
    print(json.dumps(schema, indent=2))
    return EXIT_OK


def _cmd_scenes(args: argparse.Namespace) -> int:
    for scene in SCENES.values():
        print(f"{scene.name:14s} {scene.kind:9s} {scene.runner:26s} {scene.title}")
    return EXIT_OK


def _common(config: bool) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(add_help=False)
    if config:
        p.add_argument("config", metavar="CONFIG", help="scene config (YAML)")
        p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                       help="override a config value, e.g. --set mesh.order=3 --set 'load.field_magnitude=2 T' "
                            "(repeatable; the value is read as YAML)")
    p.add_argument("-v", "--verbose", action="count", default=0,
                   help="log progress (-v: INFO, e.g. Newton iterations; -vv: DEBUG)")
    return p


def _add_run(sub) -> None:
    p = sub.add_parser("run", parents=[_common(True)], help="run a scene and write its summary",
                       description="Validate CONFIG, run its scene and write DIR/summary.json "
                                   "(plus DIR/config.json, the resolved config in internal units). "
                                   "A pipeline scene (rve) is not run: the exact snakemake command that "
                                   "builds its table is printed (exit 0). A scene failure exits 1.")
    p.add_argument("--out", metavar="DIR", help="output directory (default: results/runs/<config stem>)")
    p.set_defaults(func=_cmd_run)


def _add_validate(sub) -> None:
    p = sub.add_parser("validate", parents=[_common(True)], help="validate a config and print it resolved",
                       description="Validate CONFIG (with overrides) and print it in internal units.")
    p.add_argument("--json", action="store_true", help="print JSON instead of annotated YAML")
    p.set_defaults(func=_cmd_validate)


def _add_schema(sub) -> None:
    p = sub.add_parser("schema", parents=[_common(False)], help="print the JSON schema of a scene's config",
                       description="Print the JSON schema of the raw input of SCENE (for Snakemake's validate).")
    p.add_argument("scene", metavar="SCENE", help=f"scene name ({', '.join(SCENES)})")
    p.set_defaults(func=_cmd_schema)


def _add_scenes(sub) -> None:
    p = sub.add_parser("scenes", parents=[_common(False)], help="list the known scenes",
                       description="List the scenes of the registry (rve.scenes.registry): name, kind "
                                   "(scene: run in-process; pipeline: built by Snakemake), runner module, title.")
    p.set_defaults(func=_cmd_scenes)


# --------------------------------------------------------------------------- table
def _table_error(exc: BaseException) -> int:
    print(f"rve table: {exc}", file=sys.stderr)
    return EXIT_CONFIG


def _parse_param(text: str):
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise ValueError(f"--param needs NAME=VALUE, got {text!r}")
    try:
        return name.strip(), float(value)
    except ValueError:
        return name.strip(), value.strip()


def _format_interpolated(ds, method: str) -> str:
    """One block per (mode, strain): ``name[labels] = value units`` lines."""
    import numpy as np

    lines = []
    modes = [ds["mode"].item()] if ds["mode"].ndim == 0 else list(ds["mode"].values)
    strains = [float(ds["strain"])] if ds["strain"].ndim == 0 else [float(s) for s in ds["strain"].values]
    fixed = [f"{d}={ds[d].item()}" for d in ds.coords
             if ds[d].ndim == 0 and d not in ("mode", "strain")]
    for m in modes:
        for s in strains:
            one = ds
            if "mode" in ds.dims:
                one = one.sel(mode=m)
            if "strain" in ds.dims:
                one = one.sel(strain=s)
            head = f"mode={m} strain={s:g} method={method}"
            lines.append("# " + " ".join([head] + fixed))
            for name, var in one.data_vars.items():
                units = var.attrs.get("units", "")
                dims = list(var.dims)
                for index in np.ndindex(var.shape):
                    labels = ",".join(str(one[d].values[i]) for d, i in zip(dims, index))
                    tag = f"{name}[{labels}]" if labels else name
                    lines.append(f"{tag} = {float(var.values[index]):.10g} {units}".rstrip())
    return "\n".join(lines) + "\n"


def _cmd_table(args: argparse.Namespace) -> int:
    from . import tables

    try:
        ds = tables.open_table(args.path)
        if args.table_command == "summary":
            sys.stdout.write(tables.summarize(ds))
        elif args.table_command == "interpolate":
            params = dict(_parse_param(p) for p in args.params)
            strain = args.strain if len(args.strain) > 1 else args.strain[0]
            out = tables.interpolate(ds, strain, mode=args.mode, method=args.method, **params)
            if args.variables:
                missing = [v for v in args.variables if v not in out.data_vars]
                if missing:
                    raise ValueError(f"unknown variable {missing[0]!r} (known: {', '.join(out.data_vars)})")
                out = out[args.variables]
            if args.json:
                print(json.dumps(tables.to_json_dict(out), indent=1))
            else:
                sys.stdout.write(_format_interpolated(out, args.method))
        elif args.table_command == "export":
            from .tables.formats import MACRO_FORMATS, export_macro

            if args.format in MACRO_FORMATS:
                paths = export_macro(ds, args.out, args.format, thickness=args.thickness,
                                     keep_pretension=args.keep_pretension, modes=args.modes or None,
                                     params=dict(_parse_param(p) for p in args.params),
                                     lcid_start=args.lcid_start, units=args.units, strain=args.strain,
                                     source=str(args.path))
            else:
                paths = tables.export_table(ds, args.out, args.format)
            for path in paths:
                print(f"rve: wrote {path}", file=sys.stderr)
        elif args.table_command == "plot":
            for path in tables.plot_table(ds, args.out):
                print(f"rve: wrote {path}", file=sys.stderr)
    except (ValueError, KeyError, OSError) as exc:
        return _table_error(exc)
    return EXIT_OK


def _add_table(sub) -> None:
    p = sub.add_parser("table", parents=[_common(False)], help="inspect, interpolate, export a lookup table",
                       description="Work with an RVE lookup table (netCDF written by rve.tables; "
                                   "docs/lookup_tables.md).")
    tsub = p.add_subparsers(dest="table_command", metavar="ACTION", required=True)
    s = tsub.add_parser("summary", parents=[_common(False)], help="print a summary of the table")
    s.add_argument("path", metavar="PATH", help="lookup table (.nc)")
    i = tsub.add_parser("interpolate", parents=[_common(False)], help="print values at given strains",
                        description="Interpolate the table at one or more strains (exact at stored "
                                    "strains; outside the table range is an error).")
    i.add_argument("path", metavar="PATH", help="lookup table (.nc)")
    i.add_argument("--mode", help="deformation mode (uniaxial, shear; default: all modes)")
    i.add_argument("--strain", type=float, action="append", required=True,
                   help="strain to interpolate at (repeatable)")
    i.add_argument("--method", choices=("linear", "cubic"), default="linear",
                   help="linear, or cubic = monotone PCHIP (default: linear)")
    i.add_argument("--param", dest="params", action="append", default=[], metavar="NAME=VALUE",
                   help="swept parameter value, e.g. --param fibril_radius=0.15 (repeatable)")
    i.add_argument("--var", dest="variables", action="append", default=[], metavar="NAME",
                   help="print only this variable (repeatable)")
    i.add_argument("--json", action="store_true", help="print JSON instead of text")
    e = tsub.add_parser("export", parents=[_common(False)], help="export for macroscale FE codes")
    e.add_argument("path", metavar="PATH", help="lookup table (.nc)")
    e.add_argument("--format", required=True,
                   choices=("abaqus", "lsdyna", "curves", "comsol", "hermite", "spice", "csv", "json", "dat"),
                   help="abaqus (*FABRIC include), lsdyna (*DEFINE_CURVE_TITLE + *MAT_FABRIC skeleton), curves "
                        "(one CSV per curve), comsol (spreadsheet), hermite (JSON splines), spice (.subckt "
                        "rve_cell + a static variant), csv (long table), json, dat (whitespace lookup per mode); "
                        "docs/macro_export.md")
    e.add_argument("--out", required=True, metavar="FILE",
                   help="output file (dat: FILE's stem + .<mode> + suffix per mode; curves: + .<curve>; "
                        "spice: also FILE's stem + .static)")
    e.add_argument("--thickness", default=None, metavar="T",
                   help="sheet thickness for stresses and densities (abaqus, lsdyna), e.g. '1 mm' (default 1 mm)")
    e.add_argument("--keep-pretension", action="store_true",
                   help="keep the relaxed cell's force at zero strain in the curves (default: removed, stated)")
    e.add_argument("--mode", dest="modes", action="append", default=[], metavar="MODE",
                   help="use only this mode's curves (repeatable; spice: the mode of R(strain), default uniaxial)")
    e.add_argument("--param", dest="params", action="append", default=[], metavar="NAME=VALUE",
                   help="swept parameter value (repeatable; numbers between stored values are interpolated "
                        "linearly; lsdyna: one numeric parameter may stay free, written as *DEFINE_TABLE_2D)")
    e.add_argument("--lcid-start", type=int, default=1001, metavar="N",
                   help="first LS-DYNA curve id (default 1001)")
    e.add_argument("--units", default=None, metavar="SET",
                   help="consistent unit set of the macro exports: mm-ms-g-N-MPa (the table's, default), "
                        "mm-s-t-N-MPa, m-s-kg-N-Pa, mm-ms-kg-kN-GPa")
    e.add_argument("--strain", type=float, default=0.0,
                   help="strain of the static SPICE variant (default 0)")
    g = tsub.add_parser("plot", parents=[_common(False)], help="write PNG figures of the table")
    g.add_argument("path", metavar="PATH", help="lookup table (.nc)")
    g.add_argument("--out", required=True, metavar="PREFIX", help="PNG path prefix")
    p.set_defaults(func=_cmd_table)


# --------------------------------------------------------------------------- check
def _check_one(path: Path, residual: bool, quarantine: bool = False) -> str:
    """One line of ``rve check`` for ``path``; raises on a failed check."""
    from .io.checksum import CorruptFileError, open_netcdf, verify

    if path.suffix in (".yaml", ".yml"):
        cfg = load_config(path)
        if cfg.scene == "rve":
            from .homogenisation.preflight import estimate_memory_mb, preflight

            preflight(cfg)
            return f"config {cfg.scene}: valid; pre-flight checks passed (~{estimate_memory_mb(cfg):,.0f} MB a job)"
        return f"config {cfg.scene}: valid"
    seal = verify(path)
    ds = open_netcdf(path)
    how = f"sha256 {seal.digest[:12]}... verified" if seal.sealed else "no checksum (unverified: older file)"
    if "rve_state_format" in ds.attrs:
        from .homogenisation.checkpoint import load_state

        st = load_state(path)
        text = f"state {st.kind}{f' {st.mode} step {st.step}' if st.mode else ''}, {st.x.shape[0]} nodes, {how}"
        if residual and st.config:
            from .fabrics.setup import fabric_and_mesh
            from .homogenisation.jobs import verify_equilibrium

            cfg = load_config(st.config)
            fab, mesh = fabric_and_mesh(cfg)
            got, rec = (verify_equilibrium(cfg, fab, mesh, st, path, quarantine) if st.kind != "initial"
                        else (None, None))
            if got is not None:
                text += f"; |F| recomputed {got:.3e} N (recorded {rec:.3e} N)"
        return text
    if "rve_table_format" in ds.attrs:
        from .tables import open_table
        from .tables.summary import unconverged_entries

        tab = open_table(path)
        bad = unconverged_entries(tab)
        return (f"table {tab.attrs.get('rve_table_format')}, dims " + ", ".join(f"{d}={n}" for d, n in tab.sizes.items())
                + f", {how}" + (f"; {len(bad)} entries NOT CONVERGED" if bad else ""))
    raise CorruptFileError(path, "neither an rve state nor an rve table (no rve_state_format / rve_table_format)",
                           hint="")


def _cmd_check(args: argparse.Namespace) -> int:
    from .io.checksum import CorruptFileError, quarantine

    failed = 0
    for name in args.paths:
        path = Path(name)
        try:
            if not path.exists():
                raise FileNotFoundError(f"{path}: no such file")
            line = _check_one(path, not args.no_residual, args.quarantine)
            print(f"OK   {path}: {line}")
        except ConfigError as exc:
            failed += 1
            print(f"FAIL {path}: invalid configuration:" + "".join(f"\n       {e}" for e in exc.errors))
        except (CorruptFileError, FileNotFoundError, ValueError, OSError) as exc:
            failed += 1
            text = str(exc)
            print(f"FAIL {text if text.startswith(str(path)) else f'{path}: {text}'}")
            if args.quarantine and path.exists() and path.suffix == ".nc" and "moved to" not in text:
                dest = quarantine(path)
                if dest is not None:
                    print(f"     moved to {dest} (the job that wrote it reruns on the next snakemake call)")
    print(f"rve check: {len(args.paths) - failed} of {len(args.paths)} passed", file=sys.stderr)
    return EXIT_OK if failed == 0 else EXIT_SCENE_FAILED


def _add_check(sub) -> None:
    p = sub.add_parser("check", parents=[_common(False)],
                       help="verify states and tables (checksums, equilibrium) and configs (pre-flight)",
                       description="Verify every PATH: an RVE state (SHA-256 trailer, format, equilibrium residual "
                                   "recomputed against the recorded one), a lookup table (trailer, format, "
                                   "converged flags) or a config (validation; for scene rve also the pre-flight "
                                   "checks). Exit code 0 if all pass, 1 otherwise.")
    p.add_argument("paths", nargs="+", metavar="PATH", help="state (.nc), table (.nc) or config (.yaml)")
    p.add_argument("--quarantine", action="store_true",
                   help="move a failing .nc file to <name>.corrupt so Snakemake reruns the job that wrote it")
    p.add_argument("--no-residual", action="store_true", help="do not recompute the equilibrium residual of states")
    p.set_defaults(func=_cmd_check)


_SUBCOMMANDS: list[Callable] = [_add_run, _add_validate, _add_schema, _add_scenes, _add_table, _add_check]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rve", description="Fibril-level textile simulation: scenes, configs and lookup tables.")
    parser.add_argument("--version", action="version", version=f"rve {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``rve`` script; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits on --help / usage errors
        return int(exc.code) if isinstance(exc.code, int) else EXIT_CONFIG
    _setup_logging(args.verbose)
    try:
        return args.func(args)
    except BrokenPipeError:  # output piped into `head` and the like
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
