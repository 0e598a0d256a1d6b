"""The chain of ``trackproc batch``: the step registry, what a step reads and writes, the configured chain.

A step is a small adapter (:class:`Step`) around one pipeline function (the adapters are in
:mod:`trackproc.pipeline.batch.steps`); :data:`CHAIN` fixes where each runs, and a configured
chain (:func:`make_chain`) is a subsequence of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

from trackproc.errors import InputError

#: The canonical order of the chain; a configured chain is a subsequence of it.
CHAIN = ("ingest", "smooth", "refine", "estimate", "filter")


@dataclass
class InputContext:
    """What an input step reads and writes.

    ``name`` (result name), ``source`` (the input's path, as errors and metadata name it),
    ``data`` (its bytes), ``files`` (``"section.key"`` -> bytes of the files the settings name),
    ``paths`` (``"section.key"`` -> path), ``table`` (the :class:`~trackproc.io.passfile.PassTable`
    handed from step to step), ``outputs`` (suffix -> bytes, e.g. ``".smooth.json"``),
    ``numbers`` (key numbers for the summary), ``details`` (larger per-step records for
    summary.json), ``warnings``.
    """

    name: str
    source: str
    data: bytes
    files: dict
    paths: dict
    table: object = None
    outputs: dict = field(default_factory=dict)
    numbers: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


@dataclass
class WindowContext:
    """What a window step reads and writes: ``members`` is a list of (source name, pass-file
    bytes) of the window's processed inputs, in name order; the rest as :class:`InputContext`."""

    name: str
    members: list
    files: dict
    paths: dict
    outputs: dict = field(default_factory=dict)
    numbers: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


@dataclass(frozen=True)
class Step:
    """A named step: ``scope`` "input" or "window", ``run(ctx, options)`` with ``options`` the
    step's settings section, ``files``: settings (``"section.key"``) naming files whose content
    the step reads (hashed into the content key and shipped to the workers). ``table``: the step
    makes the pass table (ingest, smooth); False for an input step that only reads it and adds
    side outputs and numbers (refine): such steps run after the table steps, and changing only
    their settings redoes only them, from the stored pass table."""

    name: str
    scope: str
    run: Callable
    files: tuple = ()
    table: bool = True


STEPS: dict[str, Step] = {}


def register(step: Step) -> Step:
    """Make ``step`` available to chains (its name must be in :data:`CHAIN`)."""
    if step.name not in CHAIN:
        raise ValueError(f"step {step.name!r} has no place in CHAIN {CHAIN}")
    if step.scope not in ("input", "window", "sequence"):
        raise ValueError(f"step scope must be 'input', 'window' or 'sequence', not {step.scope!r}")
    STEPS[step.name] = step
    return step


@dataclass(frozen=True)
class Chain:
    """The configured chain: input steps, then window steps, then sequence steps (one run over
    every processed input in time order, carried from run to run: ``filter``); names in
    :data:`CHAIN` order."""

    input_steps: tuple
    window_steps: tuple
    sequence_steps: tuple = ()

    @property
    def names(self) -> tuple:
        return self.input_steps + self.window_steps + self.sequence_steps

    @property
    def table_steps(self) -> tuple:
        """The input steps that make the pass table (``passes/<name>.parquet``)."""
        return tuple(n for n in self.input_steps if STEPS[n].table)

    @property
    def side_steps(self) -> tuple:
        """The input steps after them that only read the table (their own content key stage)."""
        return tuple(n for n in self.input_steps if not STEPS[n].table)

    @property
    def reads_raw(self) -> bool:
        """True when the inputs are raw files for ``ingest``; else canonical pass files."""
        return bool(self.input_steps) and self.input_steps[0] == "ingest"

    def files(self, scope: str) -> tuple:
        """Settings naming files the steps of ``scope`` read: "input", "window", or the two stages
        of the input steps, "table" and "side"."""
        names = {"input": self.input_steps, "window": self.window_steps, "table": self.table_steps,
                 "side": self.side_steps, "sequence": self.sequence_steps}[scope]
        return tuple(sorted({f for n in names for f in STEPS[n].files}))


def make_chain(names: Sequence[str]) -> Chain:
    """Validate a configured chain (names known, in order, none twice)."""
    names = [str(n).strip().lower() for n in names if str(n).strip()]
    if not names:
        raise InputError("no steps", column="batch.steps", expected="a subsequence of " + ", ".join(CHAIN))
    for name in names:
        if name not in CHAIN:
            raise InputError("unknown step", column="batch.steps", found=name,
                             expected="steps among " + ", ".join(CHAIN))
    if len(set(names)) != len(names) or names != sorted(names, key=CHAIN.index):
        raise InputError("steps out of order or repeated", column="batch.steps", found=", ".join(names),
                         expected="each step at most once, in the order " + " -> ".join(CHAIN))
    input_steps = tuple(n for n in names if STEPS[n].scope == "input")
    window_steps = tuple(n for n in names if STEPS[n].scope == "window")
    sequence_steps = tuple(n for n in names if STEPS[n].scope == "sequence")
    tables = [STEPS[n].table for n in input_steps]
    if tables != sorted(tables, reverse=True):  # the registry's promise, not the user's error
        raise ValueError(f"input steps that only read the pass table must follow those that make it: {input_steps}")
    return Chain(input_steps, window_steps, sequence_steps)

