"""Cut points: the significand product as one uninterpreted function.

A SAT solver cannot tell that two differently built ``17 x 17`` multipliers agree; the
multiplier proofs therefore need no multiplier reasoning at all. :func:`cut_products`
replaces every ``bvmul`` of two zero-extended operands in a formula by ``f(x, y)``, one
uninterpreted function ``f`` of the two ``M+1``-bit operands shared by every side of the
proof. Any proof that holds for *every* ``f`` holds for the real product (that ``f`` is
one of them), and two sides that multiply equal operands get equal products (functional
consistency), which is all an equivalence needs.

A ``bvmul`` whose operands are not visibly zero-extended from at most ``M+1`` bits is
refused (``ValueError``): cutting it would not be sound in this form. Products with a
constant operand (none in the FP units) are left alone.

A synthesised netlist multiplies in its DSP block's own width (``MULT18X18D``: two 18-bit
operands, sign- or zero-extended by a mode register, into 36 bits), so its operands are not
visibly narrow: they are the block's input registers. With ``guarded``,
:func:`cut_products` cuts such a product too, as
``if (higher bits of both operands zero) then f(low bits) else x * y``: exact for the real
product whatever the guard, so still sound, and where the guard holds (every reachable
state of the netlist, which the solver sees from the registers' inputs) the product is the
shared ``f`` and needs no multiplier reasoning.
"""

from __future__ import annotations

import z3

__all__ = ["product_function", "cut_products", "count_products"]


def product_function(width: int, name: str = "sigprod") -> z3.FuncDeclRef:
    """``f : BV(width) x BV(width) -> BV(2 * width)``, the cut product."""
    return z3.Function(name, z3.BitVecSort(width), z3.BitVecSort(width),
                       z3.BitVecSort(2 * width))


def _narrow(term):
    """The term a zero extension extends, or ``None``: ``ZeroExt(n, x)`` gives ``x``,
    ``Concat(c, x...)`` with a constant ``c`` gives ``Concat(c', x...)``, ``c'`` being ``c``
    without its leading zeros."""
    if term.decl().kind() == z3.Z3_OP_ZERO_EXT:
        return term.arg(0)
    if term.decl().kind() == z3.Z3_OP_CONCAT and term.num_args() >= 2:
        head = term.arg(0)
        if z3.is_bv_value(head):
            # a constant head is a zero extension of its significant bits (the
            # multiplier's operands carry a constant hidden 1 under the fraction)
            rest = [term.arg(i) for i in range(1, term.num_args())]
            bits = head.as_long().bit_length()
            if bits:
                rest = [z3.BitVecVal(head.as_long(), bits)] + rest
            return rest[0] if len(rest) == 1 else z3.Concat(*rest)
    return None


def count_products(formula: z3.BoolRef) -> int:
    """The number of distinct non-constant ``bvmul`` terms in ``formula``."""
    seen, count, stack = set(), 0, [formula]
    while stack:
        t = stack.pop()
        if t.get_id() in seen or not z3.is_app(t):
            continue
        seen.add(t.get_id())
        if t.decl().kind() == z3.Z3_OP_BMUL and not any(
                z3.is_bv_value(t.arg(i)) for i in range(t.num_args())):
            count += 1
        stack.extend(t.children())
    return count


def _fit(term, width):
    size = term.size()
    return term if size == width else z3.ZeroExt(width - size, term)


def _low(term, width, guards):
    """``term``'s low ``width`` bits; that its higher bits are zero goes to ``guards``."""
    size = term.size()
    if size <= width:
        return term
    guards.append(z3.Extract(size - 1, width, term) == 0)
    return z3.Extract(width - 1, 0, term)


def cut_products(formula: z3.BoolRef, f: z3.FuncDeclRef,
                 guarded: bool = False) -> tuple[z3.BoolRef, int]:
    """Replace every non-constant ``bvmul`` in ``formula`` by ``f`` of its operands.

    With ``guarded``, a product whose operands are not visibly zero-extended is cut too,
    under the guard that their higher bits are zero (module docstring).

    Returns
    -------
    (formula, count)
        The cut formula and the number of products replaced.

    Raises
    ------
    ValueError
        For a product whose operands are not zero-extended from at most ``f``'s operand
        width.
    """
    width = f.domain(0).size()
    seen, pairs, stack = set(), [], [formula]
    while stack:
        t = stack.pop()
        if t.get_id() in seen or not z3.is_app(t):
            continue
        seen.add(t.get_id())
        if t.decl().kind() == z3.Z3_OP_BMUL:
            args = [t.arg(i) for i in range(t.num_args())]
            if any(z3.is_bv_value(x) for x in args):
                stack.extend(args)
                continue
            narrow, guards = [_narrow(x) for x in args], []
            if guarded and len(args) == 2:
                narrow = [_low(x if n is None or n.size() > width else n, width, guards)
                          for x, n in zip(args, narrow)]
            if len(args) != 2 or any(n is None or n.size() > width for n in narrow):
                raise ValueError(f"cannot cut the product {t.sexpr()[:200]}: its operands are "
                                 f"not zero-extended from at most {width} bits")
            prod = f(_fit(narrow[0], width), _fit(narrow[1], width))
            size = t.size()
            prod = z3.ZeroExt(size - 2 * width, prod) if size >= 2 * width else \
                z3.Extract(size - 1, 0, prod)
            if guards:
                prod = z3.If(z3.And(*guards), prod, t)
            pairs.append((t, prod))
            stack.extend(narrow)   # a product inside an operand is cut too
            continue
        stack.extend(t.children())
    if not pairs:
        return formula, 0
    return z3.substitute(formula, *pairs), len(pairs)
