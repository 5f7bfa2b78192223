"""Light-path expressions in Heckbert's notation: a regular-expression matcher over L, D, S, E.

Heckbert ("Adaptive Radiosity Textures for Bidirectional Ray Tracing",
SIGGRAPH 1990) writes a light path as a string from the light to the eye:
L a light, D a diffuse reflection, S a specular one, E the eye. A Whitted
tracer produces exactly the paths L E, L S+ E, L D E and L D S+ E.

An expression is a regular expression over those four letters:
concatenation, ``|``, ``*``, ``+``, ``?``, parentheses, ``.`` (any letter)
and classes such as ``[DS]``; spaces are ignored. Examples: ``LDE``,
``LDS+E``, ``LS*E``, ``L(D|S)*E``.

The tracer walks paths from the eye, so it needs the reversed language: the
expression's syntax tree is reversed (every concatenation read backwards),
compiled to an NFA (Thompson 1968) and then to a DFA by the subset
construction. Each ray carries one DFA state; a vertex appends its letter by a
table look-up, and light reaching the eye counts only if the state after the
final ``L`` accepts. States from which no accepting state can be reached are
dead: rays in them carry nothing the expression wants and are dropped.

Size is bounded before any work: at most ``MAX_SYMBOLS`` symbols and
``MAX_NESTING`` levels of parentheses, and at most ``WHITTED_LPE_MAX_STATES``
DFA states (default 1000; tracer/limits.py). The subset construction can need
2^n states for n symbols (``L.{n}D.*E``: the n-th letter from the end must be
a D), so it stops and refuses the expression when it passes the limit; the
NFA has at most 2 states per symbol (``+`` is its own node, never a copy of
its operand), so the work per DFA state is bounded too.
"""

from __future__ import annotations

from dataclasses import dataclass

from whitted.tracer.errors import UserError

ALPHABET = "LDSE"
SYMBOL = {c: i for i, c in enumerate(ALPHABET)}
#: Longest expression (symbols, spaces not counted) and deepest nesting of parentheses.
MAX_SYMBOLS = 200
MAX_NESTING = 32


# ---------------------------------------------------------------- parsing


def _short(expr: str) -> str:
    return repr(expr if len(expr) <= 60 else expr[:60] + "...")


class LPEError(UserError):
    pass


def _parse(expr: str):
    """Syntax tree: ('sym', set) | ('cat', a, b) | ('alt', a, b) | ('star', a) | ('eps',)."""
    text = expr.replace(" ", "")
    if not text:
        raise LPEError("empty light-path expression")
    if len(text) > MAX_SYMBOLS:
        raise LPEError(f"light-path expression of {len(text):,} symbols: at most "
                       f"{MAX_SYMBOLS} are accepted")
    depth = deepest = 0
    for c in text:
        depth += (c == "(") - (c == ")")
        deepest = max(deepest, depth)
    if deepest > MAX_NESTING:
        raise LPEError(f"light-path expression nested {deepest} parentheses deep: at most "
                       f"{MAX_NESTING} levels are accepted")
    pos = 0

    def peek():
        return text[pos] if pos < len(text) else None

    def eat(c):
        nonlocal pos
        if peek() != c:
            raise LPEError(f"light-path expression {_short(expr)}: expected {c!r} at "
                           f"position {pos}")
        pos += 1

    def alt():
        node = cat()
        while peek() == "|":
            eat("|")
            node = ("alt", node, cat())
        return node

    def cat():
        node = None
        while peek() is not None and peek() not in "|)":
            item = postfix()
            node = item if node is None else ("cat", node, item)
        return node if node is not None else ("eps",)

    def postfix():
        node = atom()
        while peek() in ("*", "+", "?"):
            op = peek()
            eat(op)
            if op == "*":
                node = ("star", node)
            elif op == "+":
                node = ("plus", node)
            else:
                node = ("alt", node, ("eps",))
        return node

    def atom():
        nonlocal pos
        c = peek()
        if c == "(":
            eat("(")
            node = alt()
            eat(")")
            return node
        if c == "[":
            end = text.find("]", pos)
            if end < 0:
                raise LPEError(f"light-path expression {_short(expr)}: unclosed '['")
            letters = set(text[pos + 1:end])
            bad = letters - set(ALPHABET)
            if bad or not letters:
                raise LPEError(f"light-path expression {_short(expr)}: a class takes letters of "
                               f"{ALPHABET}, got [{text[pos + 1:end]}]")
            pos = end + 1
            return ("sym", frozenset(letters))
        if c == ".":
            pos += 1
            return ("sym", frozenset(ALPHABET))
        if c is not None and c in ALPHABET:
            pos += 1
            return ("sym", frozenset(c))
        raise LPEError(f"light-path expression {_short(expr)}: unexpected {c!r} at position {pos} "
                       f"(use the letters {', '.join(ALPHABET)} and | * + ? ( ) [ ] .)")

    tree = alt()
    if pos != len(text):
        raise LPEError(f"light-path expression {_short(expr)}: unexpected {text[pos]!r} at {pos}")
    return tree


def _reverse(node):
    kind = node[0]
    if kind == "cat":
        return ("cat", _reverse(node[2]), _reverse(node[1]))
    if kind == "alt":
        return ("alt", _reverse(node[1]), _reverse(node[2]))
    if kind in ("star", "plus"):
        return (kind, _reverse(node[1]))
    return node


# ---------------------------------------------------------------- automata


def _nfa(tree):
    """Thompson's construction: (start, accept, edges) with edges[s] = [(letter|None, t)]."""
    edges: list[list] = []

    def new():
        edges.append([])
        return len(edges) - 1

    def build(node):
        kind = node[0]
        if kind == "eps":
            s = new()
            return s, s
        if kind == "sym":
            a, b = new(), new()
            for c in node[1]:
                edges[a].append((c, b))
            return a, b
        if kind == "cat":
            s1, e1 = build(node[1])
            s2, e2 = build(node[2])
            edges[e1].append((None, s2))
            return s1, e2
        if kind == "alt":
            s, e = new(), new()
            for child in node[1:]:
                cs, ce = build(child)
                edges[s].append((None, cs))
                edges[ce].append((None, e))
            return s, e
        s, e = new(), new()  # star, or plus (which may not skip its operand)
        cs, ce = build(node[1])
        edges[s].append((None, cs))
        if kind == "star":
            edges[s].append((None, e))
        edges[ce] += [(None, cs), (None, e)]
        return s, e

    start, accept = build(tree)
    return start, accept, edges


def _closure(states, edges):
    stack, seen = list(states), set(states)
    while stack:
        s = stack.pop()
        for c, t in edges[s]:
            if c is None and t not in seen:
                seen.add(t)
                stack.append(t)
    return frozenset(seen)


@dataclass(frozen=True)
class DFA:
    """transitions[state][letter index] -> state; state 0 is the dead state."""
    expression: str
    transitions: tuple[tuple[int, ...], ...]
    accepting: tuple[bool, ...]
    start: int

    def step(self, state: int, letter: str) -> int:
        return self.transitions[state][SYMBOL[letter]]

    def matches_reversed(self, text: str) -> bool:
        """Whether ``text``, read from the eye (E first), is a path the expression describes."""
        s = self.start
        for c in text:
            s = self.step(s, c)
        return self.accepting[s]

    def matches(self, path: str) -> bool:
        """Whether ``path``, written from the light to the eye (``LDSE``), matches."""
        return self.matches_reversed(path[::-1])


def compile_lpe(expr: str) -> DFA:
    """A DFA that reads paths from the eye (E ... L) and accepts those matching ``expr``.

    Raises :class:`LPEError` for a bad or too large expression (see the module doc).
    """
    from whitted.tracer.limits import LPE_MAX_STATES

    max_states = LPE_MAX_STATES.value()
    start, accept, edges = _nfa(_reverse(_parse(expr)))
    dead = frozenset()
    index = {dead: 0}
    order = [dead]
    trans: list[list[int]] = [[0] * len(ALPHABET)]
    first = _closure({start}, edges)
    index[first] = 1
    order.append(first)
    trans.append([0] * len(ALPHABET))
    i = 1
    while i < len(order):
        cur = order[i]
        for c in ALPHABET:
            nxt = _closure({t for s in cur for d, t in edges[s] if d == c}, edges)
            if nxt not in index:
                if len(order) >= max_states:
                    raise LPEError(
                        f"light-path expression {_short(expr)}: its automaton needs more than "
                        f"{max_states:,} states (set WHITTED_LPE_MAX_STATES to change the "
                        "limit)")
                index[nxt] = len(order)
                order.append(nxt)
                trans.append([0] * len(ALPHABET))
            trans[i][SYMBOL[c]] = index[nxt]
        i += 1
    accepting = [accept in st for st in order]
    # Dead: no accepting state reachable. Map them all to state 0.
    alive = set(k for k, a in enumerate(accepting) if a)
    changed = True
    while changed:
        changed = False
        for k, row in enumerate(trans):
            if k not in alive and any(t in alive for t in row):
                alive.add(k)
                changed = True
    trans = [[t if t in alive else 0 for t in row] for row in trans]
    return DFA(expr, tuple(tuple(r) for r in trans), tuple(accepting), 1 if 1 in alive else 0)
