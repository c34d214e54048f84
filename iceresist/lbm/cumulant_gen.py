"""Source generator of the D3Q27 cumulant collision (Geier, Schönherr, Pasquali and Krafczyk 2015).

The collision is written as straight-line code over 27 named scalars in five stages
(Geier et al. 2015, sections 3-4 and appendix J):

1. macroscopic values with the half-force shift, u = (j + F/2) / rho;
2. central moments of the stored deviations f~ = f - w by the chimera transform,
   three 1-D passes (z, y, x) over lines of three populations;
3. cumulants of the central moments, relaxed: shear (off-diagonal and deviatoric
   second order) with ``omega``, the trace with ``omega_bulk``, orders 3-6 with
   ``omega_higher``; the equilibrium cumulants are rho/3 for the diagonal second
   order and 0 above;
4. back from cumulants to central moments; the first-order central moments,
   -F/2 before the collision, are reflected to +F/2 so the step adds exactly F;
5. the inverse chimera transform (x, y, z) back to deviations f~'.

Well-conditioning in float32: no O(1) number is ever formed. With
E_abc the central moments of the equilibrium per unit density (1, 1/3, 1/9, 1/27) and
W_abc(u) = (central moments of the weights about u) - E_abc, a polynomial in u without
constant term (the D3Q27 weights factor into (1/6, 2/3, 1/6) per axis), the code
works on the deviations n_abc = kappa_abc - rho E_abc = kappa~_abc + W_abc(u) - drho E_abc,
where kappa~ are the central moments of f~. The cumulant relations are expanded
symbolically in n so that every rho E term cancels exactly before code is emitted.
"""

from __future__ import annotations

import ast
import itertools
from functools import lru_cache

import sympy as sp
from sympy.printing.str import StrPrinter

from iceresist.lattice import C, index_of

#: Velocity component -1, 0, 1 -> a letter used in generated names.
_V = {-1: "m", 0: "0", 1: "p"}
_AXES = "xyz"
EXPONENTS = list(itertools.product(range(3), repeat=3))


def _order(e) -> int:
    return sum(e)


def _mname(prefix: str, e) -> str:
    return f"{prefix}{e[0]}{e[1]}{e[2]}"


def equilibrium_central_moment(e) -> sp.Rational:
    """E_abc: central moment of the equilibrium per unit density, (1/3)^(a+b+c)/2 for even a, b, c, else 0."""
    out = sp.Integer(1)
    for a in e:
        out *= {0: sp.Integer(1), 1: sp.Integer(0), 2: sp.Rational(1, 3)}[a]
    return out


def weight_shift_polynomial(e, u):
    """W_abc(u): central moment about u of the lattice weights minus E_abc, expanded (no constant term)."""
    full = sp.Integer(1)
    for a, ua in zip(e, u):
        full *= {0: sp.Integer(1), 1: -ua, 2: sp.Rational(1, 3) + ua * ua}[a]
    return sp.expand(full - equilibrium_central_moment(e))


@lru_cache(maxsize=1)
def cumulant_remainders():
    """R_abc(n, 1/rho) with D_abc = C_abc - C^eq_abc = n_abc + R_abc for orders 2..6.

    C_abc = rho d^a_X d^b_Y d^c_Z ln M(X, Y, Z) at 0 (rho-weighted cumulants, Geier et al.
    2015 eq. 13), M the generating function of the 27 central moments with first order
    set to zero (forcing is applied around the collision), kappa_abc = rho E_abc + n_abc.
    Returns {exponent: expression} in symbols n_abc and ``ir`` = 1/rho.
    """
    rho, ir = sp.symbols("rho ir", positive=True)
    X, Y, Z = sp.symbols("X Y Z")
    n = {e: sp.Symbol(_mname("n", e)) for e in EXPONENTS}
    kappa = {}
    for e in EXPONENTS:
        if _order(e) == 0:
            kappa[e] = rho
        elif _order(e) == 1:
            kappa[e] = sp.Integer(0)
        else:
            kappa[e] = rho * equilibrium_central_moment(e) + n[e]
    # ln M = ln rho + ln(1 + Delta); Delta starts at second order, so Delta^4 is beyond sixth order
    delta = sp.expand(sum(kappa[e] / rho * X ** e[0] * Y ** e[1] * Z ** e[2]
                          / (sp.factorial(e[0]) * sp.factorial(e[1]) * sp.factorial(e[2]))
                          for e in EXPONENTS if _order(e) >= 2))
    gens = (X, Y, Z)

    def truncate(p):
        poly = sp.Poly(p, *gens)
        return sum(c * X ** m[0] * Y ** m[1] * Z ** m[2] for m, c in poly.terms() if max(m) <= 2)

    d2 = truncate(sp.expand(delta * delta))
    d3 = truncate(sp.expand(d2 * delta))
    log_poly = sp.Poly(delta - d2 / 2 + d3 / 3, *gens)
    out = {}
    for e in EXPONENTS:
        if _order(e) < 2:
            continue
        coeff = log_poly.coeff_monomial(X ** e[0] * Y ** e[1] * Z ** e[2])
        c = sp.expand(rho * coeff * sp.factorial(e[0]) * sp.factorial(e[1]) * sp.factorial(e[2]))
        ceq = rho * equilibrium_central_moment(e) if _order(e) == 2 else sp.Integer(0)
        r = sp.expand(c - ceq - n[e])
        r = sp.expand(r.subs(rho, 1 / ir))
        if r.has(rho) or r.free_symbols - set(n.values()) - {ir}:
            raise ArithmeticError(f"cumulant remainder {e} did not reduce to n and 1/rho: {r}")
        if sp.expand(r.subs({s: 0 for s in n.values()})) != 0:
            raise ArithmeticError(f"cumulant remainder {e} keeps an O(1) term")
        out[e] = r
    return out


class _RealPrinter(StrPrinter):
    """Prints sympy expressions with every number as a typed constant name and powers as products."""

    def __init__(self, consts):
        super().__init__()
        self.consts = consts

    def _const(self, value: sp.Rational) -> str:
        p, q = int(value.p), int(value.q)
        name = f"k{p}" if q == 1 else f"k{p}_{q}"
        name = name.replace("-", "m")
        self.consts[name] = float(p) / float(q)
        return name

    def _print_Integer(self, expr):
        return self._const(expr)

    def _print_Rational(self, expr):
        return self._const(expr)

    def _print_Pow(self, expr, rational=False):
        b, e = expr.as_base_exp()
        if e.is_Integer and 1 < int(e) <= 4:
            s = self.parenthesize(b, 100)
            return "*".join([s] * int(e))
        return super()._print_Pow(expr, rational)


def _emit(pairs, consts, lines, tmp_prefix):
    """Append ``name = expr`` lines for (name, sympy expr) pairs after common-subexpression elimination."""
    printer = _RealPrinter(consts)
    names = [p[0] for p in pairs]
    exprs = [p[1] for p in pairs]
    syms = sp.numbered_symbols(tmp_prefix)
    reps, reduced = sp.cse(exprs, symbols=syms, optimizations="basic")
    for s, ex in reps:
        lines.append(f"    {s} = {printer.doprint(_name_fractions(ex, consts))}")
    for nm, ex in zip(names, reduced):
        lines.append(f"    {nm} = {printer.doprint(_name_fractions(ex, consts))}")


def _name_fractions(expr, consts):
    """Replace non-integer rational coefficients by named constants so they multiply instead of divide."""
    reps = {}
    for r in expr.atoms(sp.Rational):
        if not r.is_Integer:
            name = f"k{int(r.p)}_{int(r.q)}".replace("-", "m")
            consts[name] = float(r.p) / float(r.q)
            reps[r] = sp.Symbol(name)
    return expr.xreplace(reps)


def _chimera_forward(lines):
    """Central moments of f~ about u by three 1-D passes: z, then y, then x (Geier et al. 2015, app. J)."""
    vel = (-1, 0, 1)
    # pass z: lines along z at fixed (cx, cy) -> a_{cx cy}_{g}
    for cx in vel:
        for cy in vel:
            fm, f0, fp = (f"f{index_of(cx, cy, cz)}" for cz in vel)
            t = f"a{_V[cx]}{_V[cy]}_"
            lines.append(f"    s_ = {fm} + {fp}")
            lines.append(f"    d_ = {fp} - {fm}")
            lines.append(f"    {t}0 = s_ + {f0}")
            lines.append(f"    {t}1 = d_ - uz * {t}0")
            lines.append(f"    {t}2 = s_ - uz * (d_ + {t}1)")
    # pass y: lines along y at fixed (cx, g) -> b_{cx}_{b g}
    for cx in vel:
        for g in range(3):
            am, a0, ap = (f"a{_V[cx]}{_V[cy]}_{g}" for cy in vel)
            t = f"b{_V[cx]}_"
            lines.append(f"    s_ = {am} + {ap}")
            lines.append(f"    d_ = {ap} - {am}")
            lines.append(f"    {t}0{g} = s_ + {a0}")
            lines.append(f"    {t}1{g} = d_ - uy * {t}0{g}")
            lines.append(f"    {t}2{g} = s_ - uy * (d_ + {t}1{g})")
    # pass x: lines along x at fixed (b, g) -> c_{a b g} = central moments of f~
    for b in range(3):
        for g in range(3):
            bm, b0, bp = (f"b{_V[cx]}_{b}{g}" for cx in vel)
            lines.append(f"    s_ = {bm} + {bp}")
            lines.append(f"    d_ = {bp} - {bm}")
            lines.append(f"    c0{b}{g} = s_ + {b0}")
            lines.append(f"    c1{b}{g} = d_ - ux * c0{b}{g}")
            lines.append(f"    c2{b}{g} = s_ - ux * (d_ + c1{b}{g})")


def _chimera_backward(lines):
    """Inverse chimera transform: central moments q_abc of f~' about u -> populations, passes x, y, z."""
    vel = (-1, 0, 1)
    for b in range(3):
        for g in range(3):
            k0, k1, k2 = (f"q{a}{b}{g}" for a in range(3))
            lines.append(f"    r1_ = {k1} + ux * {k0}")
            lines.append(f"    r2_ = {k2} + ux * ({k1} + r1_)")
            lines.append(f"    b0_{b}{g} = {k0} - r2_")
            lines.append(f"    bp_{b}{g} = half * (r2_ + r1_)")
            lines.append(f"    bm_{b}{g} = half * (r2_ - r1_)")
    for cx in vel:
        for g in range(3):
            k0, k1, k2 = (f"b{_V[cx]}_{b}{g}" for b in range(3))
            t = f"a{_V[cx]}"
            lines.append(f"    r1_ = {k1} + uy * {k0}")
            lines.append(f"    r2_ = {k2} + uy * ({k1} + r1_)")
            lines.append(f"    {t}0_{g} = {k0} - r2_")
            lines.append(f"    {t}p_{g} = half * (r2_ + r1_)")
            lines.append(f"    {t}m_{g} = half * (r2_ - r1_)")
    for cx in vel:
        for cy in vel:
            k0, k1, k2 = (f"a{_V[cx]}{_V[cy]}_{g}" for g in range(3))
            lines.append(f"    r1_ = {k1} + uz * {k0}")
            lines.append(f"    r2_ = {k2} + uz * ({k1} + r1_)")
            lines.append(f"    o{index_of(cx, cy, 0)} = {k0} - r2_")
            lines.append(f"    o{index_of(cx, cy, 1)} = half * (r2_ + r1_)")
            lines.append(f"    o{index_of(cx, cy, -1)} = half * (r2_ - r1_)")


@lru_cache(maxsize=2)
def cumulant_source(higher_at_equilibrium: bool = False):
    """Source text of ``collide_cumulant(f, omega, Fx, Fy, Fz)`` and the numeric constants it uses.

    ``higher_at_equilibrium`` emits orders 3-6 set straight to their equilibrium (omega_h = 1).

    Names taken from the namespace besides the numbers: ``omega_b`` (bulk rate) and
    ``omega_h`` (rate of orders 3-6).
    """
    consts = {"half": 0.5, "one": 1.0, "zero": 0.0, "third": 1.0 / 3.0}
    lines = ["def collide_cumulant(f, omega, Fx, Fy, Fz):",
             "    " + ", ".join(f"f{q}" for q in range(27)) + " = f"]
    # 1. macroscopic values
    lines.append("    drho = " + " + ".join(f"f{q}" for q in range(27)))
    lines.append("    rho = one + drho")
    lines.append("    ir = one / rho")
    for a, comp in enumerate(_AXES):
        pos = [f"f{q}" for q in range(27) if C[q, a] == 1]
        neg = [f"f{q}" for q in range(27) if C[q, a] == -1]
        lines.append(f"    j{comp} = " + " + ".join(pos) + " - " + " - ".join(neg))
        lines.append(f"    u{comp} = (j{comp} + half * F{comp}) * ir")
    # 2. chimera forward: c_abc = central moments of f~
    _chimera_forward(lines)
    # n_abc = c_abc + W_abc(u) - drho E_abc  (orders >= 2); with the higher orders at equilibrium
    # only the second order is relaxed, and only its deviations are needed
    hi = higher_at_equilibrium
    relaxed = [e for e in EXPONENTS if _order(e) >= 2 and not (hi and _order(e) > 2)]
    u = sp.symbols("ux uy uz")
    drho = sp.Symbol("drho")
    pairs = []
    for e in relaxed:
        pairs.append((_mname("n", e), sp.Symbol(_mname("c", e)) + weight_shift_polynomial(e, u)
                      - drho * equilibrium_central_moment(e)))
    _emit(pairs, consts, lines, "w_")
    # 3. cumulant deviations D = n + R(n), relaxation
    R = cumulant_remainders()
    pairs = [(_mname("d", e), sp.Symbol(_mname("n", e)) + R[e]) for e in relaxed]
    _emit(pairs, consts, lines, "x_")
    lines.append("    gs = one - omega")
    lines.append("    gb = one - omega_b")
    lines.append("    gh = one - omega_h")
    for e in EXPONENTS:  # shear: off-diagonal second order
        if _order(e) == 2 and max(e) == 1:
            lines.append(f"    e{e[0]}{e[1]}{e[2]} = gs * d{e[0]}{e[1]}{e[2]}")
    lines.append("    tr_ = gb * (d200 + d020 + d002)")
    lines.append("    dv1_ = gs * (d200 - d020)")
    lines.append("    dv2_ = gs * (d200 - d002)")
    lines.append("    e200 = third * (tr_ + dv1_ + dv2_)")
    lines.append("    e020 = third * (tr_ - dv1_ - dv1_ + dv2_)")
    lines.append("    e002 = third * (tr_ + dv1_ - dv2_ - dv2_)")
    if not hi:
        for e in EXPONENTS:
            if _order(e) >= 3:
                lines.append(f"    {_mname('e', e)} = gh * {_mname('d', e)}")
    # 4. back to central-moment deviations p = e - R(p), order by order; at omega_h = 1 the
    # post-collision cumulants of orders 3-6 are zero, substituted symbolically so that no
    # multiplication by zero is emitted (fast-math without nnan/ninf cannot fold x * 0)
    p_of_n = {sp.Symbol(_mname("n", e)): sp.Symbol(_mname("p", e)) for e in EXPONENTS}
    zeros = {}
    p_expr = {}
    for order in range(2, 7):
        pairs = []
        for e in EXPONENTS:
            if _order(e) != order:
                continue
            cum = sp.Integer(0) if (hi and order > 2) else sp.Symbol(_mname("e", e))
            ex = sp.expand(cum - R[e].xreplace(p_of_n).xreplace(zeros))
            if ex == 0:
                zeros[sp.Symbol(_mname("p", e))] = sp.Integer(0)
                p_expr[e] = sp.Integer(0)
            else:
                pairs.append((_mname("p", e), ex))
                p_expr[e] = sp.Symbol(_mname("p", e))
        _emit(pairs, consts, lines, f"y{order}_")
    # q_abc = p_abc + drho E_abc - W_abc(u) = c_abc + (p_abc - n_abc): central moments of f~';
    # the first order, -F/2 before the collision, is reflected to +F/2
    lines.append("    q000 = drho")
    pairs = []
    for e in EXPONENTS:
        o = _order(e)
        if o == 1:
            a = e.index(1)
            lines.append(f"    {_mname('q', e)} = half * F{_AXES[a]} + u{_AXES[a]}")
        elif e in relaxed:
            lines.append(f"    {_mname('q', e)} = {_mname('c', e)} + ({_mname('p', e)} - {_mname('n', e)})")
        elif o >= 2:
            pairs.append((_mname("q", e), p_expr[e] + drho * equilibrium_central_moment(e)
                          - weight_shift_polynomial(e, u)))
    _emit(pairs, consts, lines, "z_")
    # 5. chimera backward
    _chimera_backward(lines)
    lines.append("    return (" + ", ".join(f"o{q}" for q in range(27)) + ")")
    return "\n".join(lines) + "\n", consts


def _ops(node) -> dict:
    counts = {"add": 0, "mul": 0, "div": 0}
    for sub in ast.walk(node):
        if isinstance(sub, ast.BinOp):
            if isinstance(sub.op, (ast.Add, ast.Sub)):
                counts["add"] += 1
            elif isinstance(sub.op, ast.Mult):
                counts["mul"] += 1
            elif isinstance(sub.op, ast.Div):
                counts["div"] += 1
            else:
                raise ValueError(f"unexpected operator {type(sub.op).__name__} in generated source")
        elif isinstance(sub, ast.UnaryOp) and isinstance(sub.op, ast.USub):
            counts["add"] += 1
    return counts


def count_flops(src: str) -> dict:
    """Arithmetic operations per call of generated straight-line source, dead code excluded.

    Walks the assignments backwards from the return statement (liveness), counting the binary
    operators (+ - * /) and unary minus of the live ones; multiplications by a constant 0 are
    counted as written. Returns {'add', 'mul', 'div', 'total'}.
    """
    fn = ast.parse(src).body[0]
    live = {n.id for n in ast.walk(fn.body[-1]) if isinstance(n, ast.Name)}
    counts = {"add": 0, "mul": 0, "div": 0}
    for stmt in reversed(fn.body[:-1]):
        if not isinstance(stmt, ast.Assign):
            raise ValueError("generated source must be straight-line assignments")
        targets = {n.id for t in stmt.targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        if not targets & live:
            continue
        live -= targets
        live |= {n.id for n in ast.walk(stmt.value) if isinstance(n, ast.Name)}
        for k, v in _ops(stmt.value).items():
            counts[k] += v
    counts["total"] = counts["add"] + counts["mul"] + counts["div"]
    return counts
