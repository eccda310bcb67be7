"""Quantile transfer on Dask: the same results as one machine, block-parallel.

A deployment similarity matrix too large for one machine (millions of database images,
tens of thousands of queries), held as a :class:`dask.array.Array` over chunked
storage (zarr) or computed lazily (``db_desc @ q_desc.T`` of two Dask descriptor
arrays, so that it is never stored), is thresholded by a Dask cluster:

- :func:`transfer` is :meth:`qtvpr.Calibration.transfer`: each block holds whole
  segments (a segment's threshold depends only on its own columns), preceded by the
  queries its decisions look back at (the sequence gate's window, the ``L - 1`` raw
  columns of a calibration of sequence length ``L``), and
- :func:`online` is :meth:`qtvpr.Online.push_many` on a fresh state: each block is
  preceded by the queries before it that a decision looks back at (the core's
  ``Online::lookback``: the ``window - 1`` queries of its threshold, the sequence gate's
  window, the raw columns of the sequence matching).

Both return the one-machine object (:class:`qtvpr.TransferResult`,
:class:`qtvpr.OnlineDecisions`), equal to it bit for bit, and raise its errors with its
messages (a NaN at deployment query j names column j of the whole matrix, not of its
block). The calibration is sent to the workers once (scattered to every worker when a
:class:`distributed.Client` is active, else one task of the graph), not once per block.

Blocks: the query axis of ``s_val`` keeps the input's chunks (:func:`online`), or is cut
into blocks of whole segments of about the input's chunk size (:func:`transfer`); the
database axis is merged into one chunk per block, since a query's threshold needs all of
its |DB| scores. A block therefore needs ``|DB| x block`` scores of memory on its worker:
choose the query chunks accordingly (``s_val.rechunk({1: n})``).

Computation runs on the current Dask scheduler (the active ``Client``, if any) and blocks
until the result is assembled on the caller's machine.

Needs the ``dask`` extra: ``pip install ".[dask]"`` from a clone of the repository (qtvpr
is on no package index), or Dask itself: ``pip install "dask[array]" distributed``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

try:
    import dask
    import dask.array as da
except ImportError as err:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        'qtvpr.dask needs Dask: pip install "dask[array]" distributed (the dask extra of qtvpr)'
    ) from err

import numpy as np

from qtvpr._native import Calibration, Online, OnlineDecisions, TransferResult

__all__ = ["online", "transfer"]

# A block's result, or the exception it raised: (class, message).
_Part = dict[str, Any]


def transfer(
    calibration: Calibration,
    s_val: da.Array,
    *,
    k: int | None = None,
    precision: float | None = None,
    segment_size: int | None = None,
    gate: str | None = None,
    query_major: bool = False,
    sequence_window: int | None = None,
    sequence_level: float | None = None,
    sequence_speed: float | None = None,
    sequence_tolerance: float | None = None,
    sequence_drift: float | None = None,
) -> TransferResult:
    """:meth:`qtvpr.Calibration.transfer` of a Dask array, block-parallel.

    ``s_val`` is the |DB| x |Qval| deployment similarity (|Qval| x |DB| with
    ``query_major=True``), a :class:`dask.array.Array` of float32 or float64, possibly
    lazy. The query axis is cut into blocks of whole segments of ``segment_size``
    queries, about as long as its largest chunk (at least one segment); each block is
    one task that runs the compiled transfer on it, and the results are assembled into
    the :class:`qtvpr.TransferResult` of ``calibration.transfer(s_val.compute(), ...)``,
    identical to it. Without a segment size the whole deployment set is one segment,
    hence one task. ``k``, ``precision``, ``gate`` and the sequence gate's parameters
    left as ``None`` are the calibration's (:attr:`qtvpr.Calibration.defaults`), as in
    :meth:`qtvpr.Calibration.transfer`. With the sequence gate, or a calibration of
    sequence length ``L > 1``, each block is preceded by the queries its decisions look
    back at, so that its consistencies and matched columns are those of the whole
    matrix.

    Raises what :meth:`qtvpr.Calibration.transfer` raises on the whole matrix, with the
    same messages (positions in the whole matrix), and ``TypeError`` when ``s_val`` is
    not a Dask array.
    """
    s_val = _check_array(s_val)
    _check_calibration(calibration)
    args: dict[str, Any] = {
        "k": k,
        "precision": precision,
        "gate": gate,
        "query_major": query_major,
        "sequence_window": sequence_window,
        "sequence_level": sequence_level,
        "sequence_speed": sequence_speed,
        "sequence_tolerance": sequence_tolerance,
        "sequence_drift": sequence_drift,
    }
    # What the compiled transfer refuses before reading a score, refused by it here; and
    # how many queries before a block its decisions look back at.
    lookback = calibration._check_transfer(s_val.shape, segment_size=segment_size, **args)
    _, n = _oriented_shape(s_val, query_major)
    if segment_size is None:
        starts = [0]
    else:
        per_block = segment_size * max(1, round(_largest_chunk(s_val, query_major) / segment_size))
        starts = list(range(0, n, per_block))
    bounds = list(zip(starts, [*starts[1:], n], strict=True))
    cal = _send(calibration)
    tasks = []
    for start, end in bounds:
        # A shorter last block is the last segment, kept whole.
        size = segment_size if segment_size is not None and end - start >= segment_size else None
        before = min(start, lookback)
        block = _block(s_val, start - before, end, query_major)
        tasks.append(dask.delayed(_transfer_block)(cal, block, start, before, size, args))
    parts = _computed(tasks)
    return TransferResult._from_parts(
        np.concatenate([p["thresholds"] for p in parts]),
        np.concatenate([p["quantiles"] for p in parts]),
        [segment for p in parts for segment in p["segments"]],
        np.concatenate([p["query_quantiles"] for p in parts]),
        np.concatenate([p["query_thresholds"] for p in parts]),
        np.concatenate([p["query_weights"] for p in parts]),
        np.concatenate([p["neighbours"] for p in parts]),
        # Every block has the calibration's m* (or none), and its queries' margins.
        parts[0]["gate"],
        None if parts[0]["gate"] is None else np.concatenate([p["query_margins"] for p in parts]),
        # Every block has confidences in single matching, none in multi.
        *(
            None if parts[0][name] is None else np.concatenate([p[name] for p in parts])
            for name in ("query_confidences", "query_confidences_lower95")
        ),
        # Every block has the sequence gate's level (or none), and its queries'
        # consistencies.
        parts[0]["consistency_level"],
        None
        if parts[0]["consistency_level"] is None
        else np.concatenate([p["query_consistencies"] for p in parts]),
    )


def online(
    calibration: Calibration,
    s_val: da.Array,
    *,
    k: int | None = None,
    precision: float | None = None,
    window: int | None = None,
    min_window: int | None = None,
    gate: str | None = None,
    query_major: bool = False,
    sequence_window: int | None = None,
    sequence_level: float | None = None,
    sequence_speed: float | None = None,
    sequence_tolerance: float | None = None,
    sequence_drift: float | None = None,
    sequence: int | None = None,
) -> OnlineDecisions:
    """:meth:`qtvpr.Online.push_many` of a Dask array on a fresh state, block-parallel.

    ``s_val`` is as in :func:`transfer`. ``k``, ``precision``, ``window``,
    ``min_window``, ``gate``, the sequence gate's parameters and ``sequence`` are those
    of :class:`qtvpr.Online` (``None``: the calibration's
    :attr:`qtvpr.Calibration.defaults`, and no warm-up). Each chunk of the query axis is
    one task: a fresh :class:`qtvpr.Online` is resumed from the queries before the chunk
    that a decision looks back at (the state's own count of them: its window's, the
    sequence gate's, the raw columns of a sequence length ``L``; fewer at the start of
    the stream, none for the first chunk, so that the warm-up of ``min_window`` and the
    start of the stream apply to its first queries only), then pushed the chunk. As a
    decision reads nothing older, the decisions are those of ``Online(calibration,
    ...).push_many(s_val.compute())``, identical to them, with ``queries`` numbered over
    the whole stream.

    Raises what :class:`qtvpr.Online` and :meth:`qtvpr.Online.push_many` raise on the
    whole matrix, with the same messages (positions in the whole matrix), and
    ``TypeError`` when ``s_val`` is not a Dask array.
    """
    s_val = _check_array(s_val)
    # Built here for its errors and resolved parameters (the window may come from the
    # calibration's defaults); each block builds its own.
    state = Online(
        calibration,
        k=k,
        precision=precision,
        window=window,
        min_window=min_window,
        gate=gate,
        sequence_window=sequence_window,
        sequence_level=sequence_level,
        sequence_speed=sequence_speed,
        sequence_tolerance=sequence_tolerance,
        sequence_drift=sequence_drift,
        sequence=sequence,
    )
    n_db, n = _oriented_shape(s_val, query_major)
    if n_db == 0 or n == 0:
        # No block to schedule: the (empty) matrix itself.
        return state.push_many(s_val.compute(), query_major=query_major)
    line = state.sequence_gate
    params: dict[str, Any] = {
        "k": state.k,
        "precision": state.precision,
        "window": state.window,
        "min_window": state.min_window,
        "gate": state.gate,
        **{f"sequence_{name}": value for name, value in line.items()},
    }
    chunks = s_val.chunks[0 if query_major else 1]
    starts = np.cumsum([0, *chunks[:-1]]).tolist()
    bounds = [(s, s + c) for s, c in zip(starts, chunks, strict=True) if c > 0]
    cal = _send(calibration)
    tasks = []
    for start, end in bounds:
        first = start - state._lookback(start)
        block = _block(s_val, first, end, query_major)
        tasks.append(dask.delayed(_online_block)(cal, block, first, start, params, query_major))
    parts = _computed(tasks)
    # The columns of the core's record, in its order (a gate's are None without it).
    columns = OnlineDecisions.COLUMNS
    return OnlineDecisions._from_parts(
        *(None if parts[0][name] is None else np.concatenate([p[name] for p in parts]) for name in columns)
    )


def _check_array(s_val: object) -> da.Array:
    if not isinstance(s_val, da.Array):
        raise TypeError(
            f"s_val: expected a dask.array.Array, got {type(s_val).__name__}; "
            "for a NumPy array or a .npy file use qtvpr.Calibration.transfer or qtvpr.Online.push_many"
        )
    if s_val.ndim != 2:
        raise ValueError(f"s_val: expected a 2-D similarity matrix, got {s_val.ndim} dimensions")
    if any(np.isnan(c) for axis in s_val.chunks for c in axis):
        raise ValueError("s_val: unknown chunk sizes; call s_val.compute_chunk_sizes() first")
    return s_val


def _oriented_shape(s_val: da.Array, query_major: bool) -> tuple[int, int]:
    """(|DB|, number of queries)."""
    rows, cols = s_val.shape
    return (cols, rows) if query_major else (rows, cols)


def _largest_chunk(s_val: da.Array, query_major: bool) -> int:
    return max(s_val.chunks[0 if query_major else 1])


def _block(s_val: da.Array, start: int, end: int, query_major: bool) -> da.Array:
    """Queries ``start..end`` with all their |DB| scores: one chunk, on one worker."""
    part = s_val[start:end] if query_major else s_val[:, start:end]
    return part.rechunk(part.shape)


def _check_calibration(calibration: object) -> None:
    if not isinstance(calibration, Calibration):
        raise TypeError(f"calibration: expected a qtvpr.Calibration, got {type(calibration).__name__}")


def _send(calibration: Calibration) -> Any:
    """The calibration as a task argument, sent to the workers once: scattered to
    every worker of the active distributed client, else one task of the graph."""
    _check_calibration(calibration)
    try:
        from distributed import default_client

        client = default_client()
    except (ImportError, ValueError):
        return dask.delayed(calibration)
    return client.scatter(calibration, broadcast=True, hash=False)


def _computed(tasks: list[Any]) -> list[_Part]:
    """Compute the blocks; raise the error of the first failed one, in query order (the
    one the one-machine call, which reads the queries in order, would raise)."""
    parts: list[_Part] = list(dask.compute(*tasks))
    for part in parts:
        if "error" in part:
            kind, message = part["error"]
            raise kind(message)
    return parts


def _caught(run: Callable[[], _Part]) -> _Part:
    """``run()``, or its ``ValueError`` or ``TypeError`` as a result (the compiled
    code's, whose positions are those of the whole matrix), for :func:`_computed`."""
    try:
        return run()
    except (TypeError, ValueError) as err:
        return {"error": (type(err), str(err))}


def _transfer_block(
    calibration: Calibration,
    block: np.ndarray,
    start: int,
    before: int,
    segment_size: int | None,
    args: dict[str, Any],
) -> _Part:
    """The transfer of one block of whole segments whose first query is ``start``,
    preceded in ``block`` by the ``before`` queries its decisions look back at."""

    def run() -> _Part:
        r = calibration._transfer_at(block, start, before=before, segment_size=segment_size, **args)
        return {
            "thresholds": r.thresholds,
            "quantiles": r.quantiles,
            "segments": r.segments,
            "query_quantiles": r.query_quantiles,
            "query_thresholds": r.query_thresholds,
            "query_weights": r.query_weights,
            "neighbours": r.neighbours,
            "gate": r.gate,
            "query_margins": r.query_margins,
            "query_confidences": r.query_confidences,
            "query_confidences_lower95": r.query_confidences_lower95,
            "consistency_level": r.consistency_level,
            "query_consistencies": r.query_consistencies,
        }

    return _caught(run)


def _online_block(
    calibration: Calibration, block: np.ndarray, first: int, start: int, params: dict[str, Any], query_major: bool
) -> _Part:
    """The decisions of queries ``start..`` of ``block`` (whose first query is
    ``first``), on a state resumed at ``start`` from its queries ``first..start``."""
    warm = start - first
    head, body = (block[:warm], block[warm:]) if query_major else (block[:, :warm], block[:, warm:])

    def run() -> _Part:
        state = Online(calibration, **params)
        state._resume(start, head, query_major=query_major)
        d = state._push_stream(body, query_major=query_major)
        return {name: getattr(d, name) for name in OnlineDecisions.COLUMNS}

    # An error in the resumed queries is the previous block's too, raised first by
    # _computed (blocks in query order) with the same message.
    return _caught(run)
