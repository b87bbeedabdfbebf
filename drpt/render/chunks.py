"""Chunks of a render: fixed groups of passes, and their exact merge.

A render's passes (:class:`~drpt.render.renderer.PassPlan`) are grouped into
*chunks*: chunk ``c`` is the sample steps ``[c * steps, (c + 1) * steps)``
of the plan, each with all its bands of rows, so every chunk covers the
whole image with the same number of samples per pixel (the last chunk may
have fewer). A chunk is a pure function of the scene, the render options
and its index: its passes keep their global pass indices, which select the
PCG32 streams (:meth:`Renderer._trace_pass
<drpt.render.renderer.Renderer._trace_pass>`), so a chunk traced twice, on
any process or machine, gives the same arrays.

:func:`plan_chunks` caps the plan's samples per pixel of a pass at the
chunk size, so a small image can still be cut into many chunks. Without a
chunk size a chunk is one sample step of the plan: then a render's passes,
random numbers and float64 sums are the ones of a render that adds pass
after pass (a pass's sums land in zeros, adding zeros is exact).

:class:`ChunkMerge` adds chunk results in chunk order whatever order they
arrive in (later ones wait in a buffer), so the float64 sums, and the image,
do not depend on how many processes traced the chunks, in which order they
finished, or how often one was traced again. :func:`merge` is the same for
a finished list.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .renderer import PassPlan  # an annotation only: the renderer imports this module


@dataclass(frozen=True)
class ChunkPlan:
    """Chunk ``c`` is the passes ``passes_of(c)`` of :attr:`passes`: sample
    steps ``[c * steps, (c + 1) * steps)``, every band of rows of each."""

    passes: PassPlan
    steps: int  # sample steps of the pass plan per chunk

    @property
    def sample_steps(self) -> int:
        """Sample steps of the whole render: ``ceil(spp / k)`` (``k`` samples per pixel each)."""
        return -(-self.passes.spp // self.passes.k)

    @property
    def count(self) -> int:
        """Chunks of the render: ``ceil(sample_steps / steps)`` (the last may be short)."""
        return -(-self.sample_steps // self.steps)

    def __len__(self) -> int:
        return self.count

    def passes_of(self, c: int) -> range:
        """The pass indices of chunk ``c`` (every band of rows of its sample steps);
        ``IndexError`` outside ``0 .. count - 1``."""
        if not 0 <= c < self.count:
            raise IndexError(f"chunk {c} of {self.count}")
        bands = self.passes.bands
        return range(c * self.steps * bands, min((c + 1) * self.steps * bands, self.passes.count))

    def spp_of(self, c: int) -> int:
        """Samples per pixel of chunk ``c`` (the same at every pixel)."""
        p = self.passes
        s0 = c * self.steps * p.k
        return min(self.steps * p.k, p.spp - s0)

    def spp_before(self, c: int) -> int:
        """Samples per pixel of chunks ``0..c-1``."""
        return min(c * self.steps * self.passes.k, self.passes.spp)


def plan_chunks(width: int, height: int, spp: int, max_lanes: int,
                chunk_spp: int | None = None) -> ChunkPlan:
    """The chunks of a render. A pass traces at most ``chunk_spp`` samples
    per pixel, and a chunk is the most whole sample steps of the pass plan
    that hold at most ``chunk_spp`` (at least one step); ``None`` is one
    sample step of :func:`~drpt.render.renderer.plan_passes`' plan per chunk."""
    from .renderer import plan_passes  # cycle: the renderer imports this module

    plan = plan_passes(width, height, spp, max_lanes)
    if chunk_spp is None:
        return ChunkPlan(plan, 1)
    plan = replace(plan, k=min(plan.k, chunk_spp))
    return ChunkPlan(plan, max(1, chunk_spp // plan.k))


@dataclass
class ChunkResult:
    """What one chunk returns: per-pixel sums of its samples and of their
    squares (float64, ``(H, W, 3)``), and its samples per pixel ``spp`` (every
    pixel has the same count)."""

    index: int
    spp: int
    sum: np.ndarray
    sumsq: np.ndarray
    nonfinite: int = 0  # samples dropped as NaN/Inf
    seconds: float = 0.0  # time the chunk took where it ran
    worker: str = ""  # where it ran (a Dask worker's address; "" in process)
    warnings: list[str] = field(default_factory=list)  # the scene's, from the first chunk a worker ran
    #: a splatting film's filter-weight sums, sum(w) and sum(w^2) per pixel ((H, W, 2)); None otherwise
    weight: np.ndarray | None = None
    #: the chunk's sums were added straight into the merge it was traced for
    #: (:meth:`~drpt.render.renderer.Renderer.render_chunk` with ``into``): ``sum`` and
    #: ``sumsq`` are None and pushing it only counts it
    direct: bool = False
    #: with AOVs: their channels' weighted sums, then the weights' sum ((H, W, C + 1)); None otherwise
    aov: np.ndarray | None = None


class ChunkMerge:
    """Adds chunk results in chunk order: :meth:`push` takes them in any
    order, keeps those that arrive early, and adds each when its turn comes.

    ``next`` is the first chunk not merged yet; a merge can start from a
    checkpoint's sums (``next``, ``sum``, ``sumsq``, ``nonfinite``, ``weight``).
    ``weight`` (a splatting film's ``sum(w)``, ``sum(w^2)``) is None until a
    result with weights arrives; ``aov`` (the AOVs' sums) until one with AOVs arrives."""

    def __init__(self, chunks: ChunkPlan, next: int = 0, sum: np.ndarray | None = None,
                 sumsq: np.ndarray | None = None, nonfinite: int = 0, weight: np.ndarray | None = None,
                 aov: np.ndarray | None = None):
        p = chunks.passes
        shape = (p.height, p.width, 3)
        self.chunks = chunks
        self.next = next
        #: the shapes of the sums that are zeros not made yet (:meth:`zeros`)
        self._unmade: dict[str, tuple] = {}
        self._sum = self._sumsq = None
        if sum is None:
            self.zeros("sum", shape)
        else:
            self.sum = np.array(sum, np.float64)
        if sumsq is None:
            self.zeros("sumsq", shape)
        else:
            self.sumsq = np.array(sumsq, np.float64)
        self.nonfinite = nonfinite
        self.weight = None if weight is None else np.array(weight, np.float64)
        self.aov = None if aov is None else np.array(aov, np.float64)
        self.pending: dict[int, ChunkResult] = {}
        #: a direct chunk (:attr:`ChunkResult.direct`) is being added into the sums: until it
        #: is pushed they are no merged prefix of chunks (no checkpoint may be written)
        self.dirty = False

    def zeros(self, name: str, shape: tuple) -> None:
        """Sums ``name`` (``"sum"``, ``"sumsq"``) become zeros of ``shape``, made where they are
        first read: a merge that takes a pass's arrays as its sums (the renderer's direct
        chunks) never clears them (``np.zeros`` of memory the heap reuses writes every byte)."""
        setattr(self, "_" + name, None)
        self._unmade[name] = tuple(shape)

    def shape_of(self, name: str) -> tuple:
        """The shape of sums ``name``, without making zeros not made yet."""
        shape = self._unmade.get(name)
        return shape if shape is not None else getattr(self, name).shape

    def _sums(self, name: str) -> np.ndarray:
        a = getattr(self, "_" + name)
        if a is None:
            a = np.zeros(self._unmade.pop(name), np.float64)
            setattr(self, "_" + name, a)
        return a

    def _set_sums(self, name: str, a: np.ndarray) -> None:
        self._unmade.pop(name, None)
        setattr(self, "_" + name, a)

    #: the per-pixel sums of the samples (float64)
    sum = property(lambda self: self._sums("sum"), lambda self, a: self._set_sums("sum", a))
    #: the per-pixel sums of their squares (with a moment render the channel products after them)
    sumsq = property(lambda self: self._sums("sumsq"), lambda self, a: self._set_sums("sumsq", a))

    @property
    def done(self) -> bool:
        """Whether every chunk of the render is merged."""
        return self.next >= self.chunks.count

    @property
    def spp(self) -> int:
        """Samples per pixel merged so far."""
        return self.chunks.spp_before(self.next)

    def push(self, result: ChunkResult) -> list[int]:
        """Take ``result``; return the chunks merged by it (none if it is early,
        or a chunk merged before: a result traced twice is dropped)."""
        if result.index >= self.next:
            self.pending.setdefault(result.index, result)
        merged = []
        while self.next in self.pending:
            r = self.pending.pop(self.next)
            if r.direct:  # its sums are in ours already
                self.nonfinite += r.nonfinite
                self.dirty = False
                merged.append(self.next)
                self.next += 1
                continue
            self.sum += r.sum
            if r.sumsq.shape != self.shape_of("sumsq") and ("sumsq" in self._unmade or not self.sumsq.any()):
                self.zeros("sumsq", r.sumsq.shape)  # with the channel products of a moment render
            self.sumsq += r.sumsq
            if r.weight is not None:
                if self.weight is None:
                    self.weight = np.zeros(self.sum.shape[:2] + (2,), np.float64)
                self.weight += r.weight
            if r.aov is not None:
                if self.aov is None:
                    self.aov = np.zeros_like(r.aov)
                self.aov += r.aov
            self.nonfinite += r.nonfinite
            merged.append(self.next)
            self.next += 1
        return merged


def merge(chunks: ChunkPlan, results: Iterable[ChunkResult]) -> ChunkMerge:
    """The merge of ``results`` (any order), as :class:`ChunkMerge` adds them."""
    m = ChunkMerge(chunks)
    for r in results:
        m.push(r)
    return m
