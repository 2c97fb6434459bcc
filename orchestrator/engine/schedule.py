"""The order in which a fixed-step master steps and initializes the elements of an SSP system,
derived from the connection graph and the FMUs' declared direct feedthrough, never from names.

Inputs: the elements in SSD order, the connections (source element, output, target element,
input) and, per output, the inputs it depends on directly (the modelDescription's
``ModelStructure/Outputs`` ``dependencies``: an empty list = no direct feedthrough, the
attribute absent = every input). See docs/master.md for the rule and why.

* An **algebraic loop** is a cycle of connections on which every element passes the loop's
  input straight through to the loop's output (port level): no order can give its values,
  so :func:`check_algebraic_loops` refuses it, naming the elements.
* In every other **feedback loop** (a strongly connected set of elements) one element is the
  loop's **sampler**: it steps first and reads all its inputs at t, and what it computes is
  the command the rest of the loop uses over [t, t + h] (a sampled controller with a
  zero-order hold). It is the element of the loop without direct feedthrough that receives
  signals from outside the loop (in a servo loop: the controller, where the reference meets
  the measurement); none or several: the first such element in SSD order.
* **Gauss-Seidel**: an output with direct feedthrough, or out of a sampler into its own
  loop, is computed before its consumers step (the source steps first). An output without
  direct feedthrough is a state: its consumers step first and read its value at t before
  the source advances. Ready elements step in this order: those taking a value computed in
  this step first (they use it at once), then SSD order.
* **Initialization** propagates along every connection, sources first, except the
  connections out of a state element (no direct feedthrough, not the sampler) back into its
  own loop: its initial outputs come from its parameters and need nothing from the loop.

For the TAPMP system (trajectory -> controller <-> plant, no FMU declaring feedthrough) this
gives Gauss-Seidel controller, plant, trajectory and initialization trajectory, controller, plant.
"""

from dataclasses import dataclass

from ..errors import UserError

# Orderings of one macro step (docs/master.md): one element after the other on the latest outputs,
# or all on the outputs at t (one extra step of delay in a feedback path).
ORDERINGS = ("gauss-seidel", "jacobi")
# How connections start: outputs propagated in Initialization Mode, or every connection at 0
# until the first step (FMPy's simulate_ssp).
CONNECTION_STARTS = ("propagated", "zero")


class ScheduleError(ValueError, UserError):
    """The system cannot be ordered (an algebraic loop) or a given order is invalid."""


@dataclass(frozen=True)
class Connection:
    """One SSP connection: ``source.output -> target.input``."""

    source: str
    output: str
    target: str
    input: str


def _feeds_through(feedthrough, element: str, output: str) -> bool:
    """Whether ``element.output`` depends directly on any input (``feedthrough(element, output)``
    returns the set of inputs it depends on)."""
    return bool(feedthrough(element, output))


def _sccs(nodes: list, edges: dict) -> list[list]:
    """Strongly connected components (Tarjan), each in the order of ``nodes``; ``edges``
    maps a node to the set of its successors."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ()), key=nodes.index):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(sorted(comp, key=nodes.index))

    for v in nodes:
        if v not in index:
            visit(v)
    return out


def check_algebraic_loops(elements: list[str], connections: list[Connection], feedthrough) -> None:
    """Raise ScheduleError naming the elements of every cycle of connections on which each
    element's output depends directly on the input the cycle enters by."""
    nodes, edges = [], {}
    for c in connections:
        a, b = ("out", c.source, c.output), ("in", c.target, c.input)
        edges.setdefault(a, set()).add(b)
        nodes += [a, b]
    ports = list(dict.fromkeys(nodes))
    for _, element, inp in [p for p in ports if p[0] == "in"]:
        for out in [p for p in ports if p[0] == "out" and p[1] == element]:
            if inp in feedthrough(element, out[2]):
                edges.setdefault(("in", element, inp), set()).add(out)
    loops = [comp for comp in _sccs(ports, edges)
             if len(comp) > 1 or comp[0] in edges.get(comp[0], ())]
    if loops:
        named = "; ".join(", ".join(sorted({p[1] for p in comp}, key=elements.index)) for comp in loops)
        raise ScheduleError(f"algebraic loop through direct feedthrough between the elements {named}: "
                            "every element on the loop passes its input straight to its output, so no "
                            "step order gives its values; allowed is a loop through at least one element "
                            "whose outputs do not depend directly on its inputs (ModelStructure "
                            "dependencies=\"\")")


def samplers(elements: list[str], connections: list[Connection], feedthrough) -> dict[str, str]:
    """{element: sampler of its feedback loop} for every element on a feedback loop."""
    succ = {}
    for c in connections:
        succ.setdefault(c.source, set()).add(c.target)
    out = {}
    for comp in _sccs(elements, succ):
        if len(comp) == 1 and comp[0] not in succ.get(comp[0], ()):
            continue
        inside = set(comp)
        states = [e for e in comp if any(c.source == e and c.target in inside
                                         and not _feeds_through(feedthrough, e, c.output) for c in connections)]
        entry = [e for e in states if any(c.target == e and c.source not in inside for c in connections)]
        sampler = (entry or states or comp)[0]
        out.update({e: sampler for e in comp})
    return out


def _kahn(elements: list[str], hard: dict, soft: dict, eager=lambda done, e: False) -> list[str]:
    """Order ``elements`` so that every hard and soft predecessor comes first (``hard``/``soft``
    map an element to the set of elements that must precede it); if that is impossible, soft
    ones are given up first, then hard ones, taking the first element in SSD order. Among
    ready elements those with ``eager(done, e)`` go first, then SSD order."""
    done, order = set(), []
    while len(order) < len(elements):
        left = [e for e in elements if e not in done]
        ready = [e for e in left if hard.get(e, set()) <= done and soft.get(e, set()) <= done] \
            or [e for e in left if hard.get(e, set()) <= done] or left
        pick = next((e for e in ready if eager(done, e)), ready[0])
        order.append(pick)
        done.add(pick)
    return order


def gauss_seidel_order(elements: list[str], connections: list[Connection], feedthrough) -> list[str]:
    """The default Gauss-Seidel step order (module docstring)."""
    loop = samplers(elements, connections, feedthrough)
    hard, soft, fresh = {}, {}, {}
    for c in connections:
        if c.source == c.target:
            continue
        held = loop.get(c.source) == c.source and loop.get(c.target) == c.source
        if held or _feeds_through(feedthrough, c.source, c.output):
            hard.setdefault(c.target, set()).add(c.source)
            fresh.setdefault(c.target, set()).add(c.source)
        else:
            soft.setdefault(c.source, set()).add(c.target)
    return _kahn(elements, hard, soft, lambda done, e: bool(fresh.get(e, set()) & done))


def initialization_order(elements: list[str], connections: list[Connection], feedthrough) -> list[str]:
    """The order in which elements leave initialization (module docstring)."""
    loop = samplers(elements, connections, feedthrough)
    before = {}
    for c in connections:
        if c.source == c.target:
            continue
        state_back = (loop.get(c.source) is not None and loop.get(c.source) == loop.get(c.target)
                      and loop[c.source] != c.source
                      and not _feeds_through(feedthrough, c.source, c.output))
        if not state_back:
            before.setdefault(c.target, set()).add(c.source)
    return _kahn(elements, before, {})


def check_order(order, elements: list[str]) -> list[str]:
    """An explicit step order: every element exactly once; ScheduleError names the
    missing, unknown and repeated ones."""
    if isinstance(order, str) or not all(isinstance(e, str) for e in order):
        raise ScheduleError(f"order = {order!r} is invalid: allowed is a list of every element name "
                            f"once: {', '.join(elements)}")
    order = list(order)
    missing = [e for e in elements if e not in order]
    unknown = [e for e in order if e not in elements]
    twice = sorted({e for e in order if order.count(e) > 1})
    if missing or unknown or twice:
        what = "; ".join(x for x in (missing and f"missing {', '.join(missing)}",
                                     unknown and f"unknown {', '.join(unknown)}",
                                     twice and f"repeated {', '.join(twice)}") if x)
        raise ScheduleError(f"order = {order!r} is invalid ({what}): allowed is every element of the "
                            f"system exactly once: {', '.join(elements)}")
    return order
