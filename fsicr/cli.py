"""Command line of the FSICR calculator: ``fsicr resistance | power | compare | ships``.

Bad input (a missing or unreadable ship file, an unknown key, a missing field, text where a
number belongs, a non-positive length, an angle outside (0, 90] deg, an unknown ice class)
gives one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys

from . import hullmesh, report
from .cliparser import OneLineParser
from .compare import compare_table2
from .errors import FsicrInputError, too_long_path
from .power import required_power
from .resistance import r_ch_at_waterlines
from .rules import ICE_CLASSES, PROPULSION_KINDS, parse_ice_class
from .ship import DESCRIPTIONS, FLAGS, WATERLINE_FIELDS
from .shipfile import builtin_ships, read_ship_file, resolve_ship_path, ship_from_mapping


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number (1, 2 or 3), got {text!r}") from None


def _add_ship_options(p: argparse.ArgumentParser, with_power: bool) -> None:
    p.add_argument("--ship", metavar="SHIP.toml", help="ship file (TOML) or a built-in ship name; flags override it")
    p.add_argument("--class", dest="ice_class", metavar="CLASS", help=f"ice class: {', '.join(ICE_CLASSES)}")
    g = p.add_argument_group("upper ice waterline (override the ship file)")
    for field in WATERLINE_FIELDS:
        g.add_argument(FLAGS[field], dest=field, type=_number, metavar="X", help=DESCRIPTIONS[field])
    g.add_argument("--bulbous-bow", dest="bulbous_bow", action=argparse.BooleanOptionalAction,
                   help="bulbous bow: phi1 = 90 deg in C1, C2")
    hm = p.add_argument_group("hull mesh (measure the upper-waterline inputs on it; stated values win)")
    hm.add_argument("--mesh", metavar="HULL.stl", help="closed hull surface, STL or OBJ")
    hm.add_argument("--draught", type=_number, metavar="X", help="draught of the mesh [m, at the mesh's scale]")
    hm.add_argument("--scale", type=_number, default=1.0, metavar="S",
                    help="full-scale lengths / the mesh's (e.g. 25 for a 1:25 model; default 1)")
    hm.add_argument("--mesh-unit", default="m", metavar="U", help=f"unit of the mesh's coordinates: "
                    f"{', '.join(hullmesh.UNITS)} (default m)")
    hm.add_argument("--mesh-bow", default="+x", metavar="AXIS",
                    help="the mesh's axis toward the bow: +x, -x, +y, -y (default +x; write --mesh-bow=-x)")
    hm.add_argument("--mesh-up", default="+z", metavar="AXIS", help="the mesh's axis upward (default +z)")
    lw = p.add_argument_group("lower ice waterline (optional; --lower-T starts it, others default to the upper values)")
    for field in WATERLINE_FIELDS:
        lw.add_argument("--lower-" + FLAGS[field][2:], dest="lower_" + field, type=_number, metavar="X",
                        help=DESCRIPTIONS[field])
    if with_power:
        pw = p.add_argument_group("propulsion")
        pw.add_argument(FLAGS["Dp_m"], dest="Dp_m", type=_number, metavar="X", help="propeller diameter Dp [m]")
        pw.add_argument(FLAGS["n_propellers"], dest="n_propellers", type=_whole, metavar="N", help="1, 2 or 3 propellers")
        pw.add_argument(FLAGS["propulsion"], dest="propulsion", choices=PROPULSION_KINDS,
                        help="cp: controllable pitch, fp: fixed pitch, electric, hydraulic")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _ship_from_args(args, with_power: bool):
    """Merge the ship file and the flags (flags win) and check the result."""
    data: dict = {}
    where = "ship data"
    meta = {"file": None}
    if args.ship:
        data = read_ship_file(args.ship)
        where = f"ship file {args.ship!r} + flags"
        meta["file"] = str(resolve_ship_path(args.ship))
    for field in WATERLINE_FIELDS + ("bulbous_bow",) + (("Dp_m", "n_propellers", "propulsion") if with_power else ()):
        value = getattr(args, field, None)
        if value is not None:
            data[field] = value
    if args.mesh is not None or args.draught is not None:
        measured = _measure_mesh(args)
        meta["mesh"] = {"file": args.mesh, "draught_m": args.draught, "scale": args.scale, "unit": args.mesh_unit,
                        "measured": measured, "stated": {f: data[f] for f in measured if f in data}}
        data = {**measured, **data}
        where += " + mesh"
    lower = {f: getattr(args, "lower_" + f) for f in WATERLINE_FIELDS if getattr(args, "lower_" + f) is not None}
    if lower:
        base = data.get("lower_waterline")
        data["lower_waterline"] = {**(base if isinstance(base, dict) else {}), **lower}
    ship, file_class, file_meta = ship_from_mapping(data, where)
    meta.update(file_meta)
    if args.ice_class is not None and not args.ice_class.strip():
        raise FsicrInputError(f"--class: empty; give one of {', '.join(ICE_CLASSES)}")
    text = args.ice_class if args.ice_class is not None else file_class
    if text is None:
        raise FsicrInputError(f"ice class missing: give --class ({', '.join(ICE_CLASSES)}) or ice_class in the ship file")
    return ship, parse_ice_class(text), meta


def _measure_mesh(args) -> dict:
    """The upper-waterline inputs measured on ``--mesh`` at ``--draught`` (:mod:`fsicr.hullmesh`)."""
    if args.mesh is None:
        raise FsicrInputError("--draught: given without --mesh; add --mesh HULL.stl or drop --draught")
    if args.draught is None:
        raise FsicrInputError("--draught: missing; give the mesh's draught in metres at its own scale, e.g. "
                              "--draught 0.44 for the 1:25 B-063 model")
    hull = hullmesh.read_hull_mesh(args.mesh, unit=args.mesh_unit, bow=args.mesh_bow, up=args.mesh_up)
    return hullmesh.measure(hull, args.draught, scale=args.scale)


def _cmd_resistance(args) -> int:
    ship, cls, meta = _ship_from_args(args, with_power=False)
    results = r_ch_at_waterlines(ship, cls)
    upper = results[0]
    out = _json({
        "command": "resistance",
        "name": meta.get("name", ""),
        "ice_class": cls,
        "r_ch_N": upper.r_ch_N,
        "r_ch_kN": upper.r_ch_kN,
        "r_ch_N_by_waterline": {r.waterline: r.r_ch_N for r in results},
        "waterlines": [r.to_dict() for r in results],
        **({"mesh": meta["mesh"]} if "mesh" in meta else {}),
        "warnings": [w for r in results for w in r.warnings],
    }, indent=2)                                   # refuses a result that is not finite, in text mode too
    print(out if args.json else report.format_resistance_report(results, meta))
    return 0


def _cmd_power(args) -> int:
    ship, cls, meta = _ship_from_args(args, with_power=True)
    result = required_power(ship, cls)
    out = _json({"command": "power", "name": meta.get("name", ""), **result.to_dict(),
                 **({"mesh": meta["mesh"]} if "mesh" in meta else {})}, indent=2)
    print(out if args.json else report.format_power_report(result, meta))
    return 0


def _cmd_compare(args) -> int:
    c = compare_table2()
    if args.json:
        print(_json({"command": "compare", **c}, indent=2))
    else:
        print(report.format_compare(c))
    return 0


def _cmd_ships(args) -> int:
    ships = {name: str(path) for name, path in sorted({**builtin_ships(), **hullmesh.builtin_meshes()}.items())}
    if args.json:
        print(_json({"command": "ships", "ships": ships}, indent=2))
    else:
        print("\n".join(f"{name:<14s} {path}" for name, path in ships.items()))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="fsicr", description="Finnish-Swedish Ice Class Rules 2017: brash-ice channel "
                                                "resistance R_CH and required engine output of new ships.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    r = sub.add_parser("resistance", help="R_CH with every intermediate value and the validity warnings")
    _add_ship_options(r, with_power=False)
    r.set_defaults(func=_cmd_resistance)
    w = sub.add_parser("power", help="required engine output at both ice waterlines and the class minimum")
    _add_ship_options(w, with_power=True)
    w.set_defaults(func=_cmd_power)
    c = sub.add_parser("compare", help="Bow A and Bow B of the paper's ship beside its table 2")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(func=_cmd_compare)
    s = sub.add_parser("ships", help="list the built-in ship files")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=_cmd_ships)
    return p


def _json(obj, **kw) -> str:
    """Strict JSON (no Infinity or NaN, which JSON does not have): a result that is not finite is refused."""
    try:
        return json.dumps(obj, allow_nan=False, **kw)
    except ValueError:
        raise FsicrInputError("the result is not finite (an input far outside a ship's dimensions?); check the "
                              "values given") from None


def main(argv=None) -> int:
    """Run the command line; returns the exit status (0 ok, 2 bad input)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: usage error (2) or --help (0)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        return int(args.func(args) or 0)
    except FsicrInputError as exc:
        print(f"fsicr: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        if too_long_path(exc) is None:
            raise
        print(f"fsicr: error: {too_long_path(exc)}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
