"""The lane schedulers: sequential work over many lanes of different lengths.

A lane is one (scene, start, task) rollout. Run as one vmapped loop, every lane would
take as long as the longest, and on a GPU each loop iteration costs kernel launches;
the two schedulers here make work proportional to the lanes' own lengths.

- :func:`run`, for the closed form's windows: a lane's window is a run of consecutive
  samples that need sequential work (the meta skill's rate-limited rotation, the
  gripper's collision checks). On random 10-task scenes the windows average 39
  samples with a longest of 198. It sorts the lanes by window length, longest first,
  and walks them in blocks of B lanes x W samples: column c covers samples c W .. c W
  + W - 1 of each window; the lanes still busy in column c are a prefix of the sorted
  order, so column c runs ceil(busy / B) blocks. A caller's ``per_block`` does the
  work of one block at once (a parallel pass over its B x W samples, then a W-step
  scan). Work is proportional to the sum of the windows (rounded up to W), not to the
  longest (measured on CPU: 5x less than one loop over all lanes).
- :func:`run_queue`, for stepped rollouts, whose length is known only when they end:
  B slots each hold one lane; each iteration steps every slot; a slot whose lane has
  ended writes its answers and takes the next lane of a queue (the caller's order,
  longest first, so that the rollouts that run while slots empty are short ones).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int


def run(length: Float[Array, " L"], lanes_per_block: int, samples_per_block: int, state,
        per_block: Callable) -> object:
    """Apply ``per_block`` to every block of busy lanes; returns the final ``state``.

    ``length``: each lane's window length in samples (0: nothing to do). ``state``: a
    pytree of per-lane arrays, leading axis L. ``per_block(lanes, start, valid,
    block_state) -> block_state``: ``lanes`` (B,) the lanes' indices, ``start`` (a
    float of ``length``'s dtype) the column's first sample within each window (c W),
    ``valid`` (B, W) whether a sample lies within its lane's window, ``block_state``
    the state's rows of those lanes. Blocks past the last lane repeat lane 0 with
    ``valid`` all False; a ``per_block`` must leave such rows as they are."""
    L = length.shape[0]
    B = min(lanes_per_block, L)
    W = samples_per_block
    n_blocks = -(-L // B)
    Lp = n_blocks * B
    order = jnp.argsort(-length)
    order = jnp.concatenate([order, jnp.zeros(Lp - L, order.dtype)])
    busy = jnp.concatenate([length[order[:L]], jnp.zeros(Lp - L, length.dtype)])
    offsets = jnp.arange(W, dtype=length.dtype)
    state = jax.tree.map(lambda a: a[order], state)

    def run_block(c: Int[Array, ""], b: Int[Array, ""], state):
        lanes = jax.lax.dynamic_slice(order, (b * B,), (B,))
        left = jax.lax.dynamic_slice(busy, (b * B,), (B,))
        rows = jax.tree.map(lambda a: jax.lax.dynamic_slice_in_dim(a, b * B, B), state)
        start = (c * W).astype(length.dtype)  # the column's first sample, as a float
        valid: Bool[Array, "B W"] = (start + offsets)[None, :] < left[:, None]
        rows = per_block(lanes, start, valid, rows)
        return jax.tree.map(lambda a, r: jax.lax.dynamic_update_slice_in_dim(a, r, b * B, 0),
                            state, rows)

    def run_column(c, state):
        # Lanes with more than c W samples left form a prefix of the sorted order.
        n_active_blocks = (jnp.sum(busy > (c * W).astype(busy.dtype)) + B - 1) // B

        def body(carry):
            b, state = carry
            return b + 1, run_block(c, b, state)

        _, state = jax.lax.while_loop(lambda x: x[0] < n_active_blocks, body, (0, state))
        return state

    n_columns = jnp.ceil(jnp.max(length) / W).astype(jnp.int32)
    _, state = jax.lax.while_loop(lambda x: x[0] < n_columns,
                                  lambda x: (x[0] + 1, run_column(x[0], x[1])), (0, state))
    inv = jnp.zeros(L, order.dtype).at[order[:L]].set(jnp.arange(L, dtype=order.dtype))
    return jax.tree.map(lambda a: a[inv], state)


def first_true(mask: Array, size: int) -> tuple[Array, Array, Array]:
    """The indices of the first ``size`` true entries of ``mask`` (B,) in order, 0 after
    them; where each index is to be written back (B + i past their count: dropped); and
    which entries were taken.
    A scatter of the entries' positions with unique indices, which the GPU writes in
    parallel: ``jnp.nonzero`` with a size is a scatter that XLA may not assume unique,
    61 us a step at 2^19 lanes on an H100, the largest kernel of the loop."""
    B = mask.shape[0]
    lane = jnp.arange(B, dtype=jnp.int32)
    pos = jnp.cumsum(mask, dtype=jnp.int32) - 1
    taken = mask & (pos < size)
    idx = jnp.zeros(size, jnp.int32).at[jnp.where(taken, pos, size + lane)].set(
        lane, mode="drop", unique_indices=True)
    slots = jnp.arange(size, dtype=jnp.int32)
    count = jnp.minimum(pos[-1] + 1, size)
    return idx, jnp.where(slots < count, idx, B + slots), taken


def put_at(a: Array, at: Array, v: Array) -> Array:
    """``a`` with the lanes ``at`` (last axis; out of range: dropped) set to ``v``; the
    indices are unique (:func:`first_true`)."""
    return a.at[..., at].set(v, mode="drop", unique_indices=True)


class _Queue(NamedTuple):
    """:func:`run_queue`'s carry: the slots' lanes and states, each slot's lane (-1:
    empty), the next lane of the queue to start, the answers."""

    lane: Any
    state: Any
    slot: Array
    next: Array
    result: Any


def run_queue(order: Int[Array, " L"], n_real: Int[Array, ""], slots: int, refill_share: int,
              unroll: int, begin: Callable, step: Callable, finish: Callable, result,
              rolled: bool = False):
    """Every lane of the queue ``order`` (the first ``n_real`` entries are run, in that
    order) through ``slots`` slots; returns ``result`` with every lane's answers.

    ``begin(ids, occupied) -> (lane, state)``: the constants and first states of the
    lanes ``ids`` (slots on the last axis; ``occupied`` false for empty slots), the
    state with a boolean ``live``. ``step(state, lane) -> state``: one step of every
    slot (an ended lane's step must change nothing). ``finish(lane, state) -> rows``:
    one lane's answers, the leaves of ``result`` (L, ...) less their first axis. The
    slots start empty. Each loop iteration first refills, once 1 / ``refill_share`` of
    the slots are open (or none is live): the ended slots write their answers, and
    they and the empty ones take the next lanes (at the start, until every slot holds
    one); then it takes ``unroll`` steps, as a loop of one traced step with ``rolled``,
    else each step traced (and compiled) on its own."""
    L = jax.tree.leaves(result)[0].shape[0]
    B = slots
    R = max(1, B // refill_share)
    # ``begin`` is traced once, for R lanes: the empty slots' shapes come from that
    # trace (slots on the last axis), and the refill's call finds it in jit's cache
    # (inlined, so the program is the same). A second trace, for the B slots' shapes
    # alone, took a fifth of a stepped program's trace on the 2-core CPU.
    begin = jax.jit(begin, inline=True)
    probe = jnp.arange(R, dtype=jnp.int32)
    shapes = jax.eval_shape(begin, probe, probe < 0)

    def write(result, slot, lane, state, which, valid):
        """Write the answers of the slots ``which`` (where ``valid``)."""
        pick = (lambda a: a[..., which])  # noqa: E731
        done = jax.vmap(finish, in_axes=-1)(jax.tree.map(pick, lane), jax.tree.map(pick, state))
        at = jnp.where(valid, slot[which], L + jnp.arange(which.shape[0], dtype=jnp.int32))
        return jax.tree.map(lambda a, v: a.at[at].set(v, mode="drop", unique_indices=True),
                            result, done)

    def open_slots(c: _Queue) -> Array:
        """The slots that may take a lane: ended ones, and while the queue still holds
        lanes, empty ones (every slot at the start)."""
        return ~c.state.live & ((c.slot >= 0) | (c.next < n_real))

    def refill(c: _Queue) -> _Queue:
        """Up to R open slots write their ended rollouts and take the next lanes of the
        queue."""
        state = c.state
        free = open_slots(c)
        idx, at, _ = first_true(free, R)
        n_free = jnp.minimum(jnp.sum(free, dtype=jnp.int32), R)
        taking = jnp.arange(R, dtype=jnp.int32)
        result = write(c.result, c.slot, c.lane, state, idx,
                       (taking < n_free) & (c.slot[idx] >= 0))
        n_new = jnp.minimum(n_free, n_real - c.next)
        new = taking < n_new
        ids = order[jnp.minimum(c.next + taking, L - 1)]
        lane_new, state_new = begin(ids, new)
        put = (lambda a, v: put_at(a, at, v))  # noqa: E731
        slot = put(c.slot, jnp.where(new, ids, -1))
        return _Queue(jax.tree.map(put, c.lane, lane_new), jax.tree.map(put, state, state_new),
                      slot, c.next + n_new, result)

    def refills(c: _Queue) -> _Queue:
        """Refill once 1 / ``refill_share`` of the slots are open (or none is live):
        once an iteration, and at the start until every slot holds a lane. One traced
        refill (and ``begin``) serves both: starting from a full first ``begin`` of
        every slot compiled it twice (a quarter of a stepped program's compile time on
        the 2-core CPU)."""
        def more(x):
            k, c = x
            n_free = jnp.sum(open_slots(c), dtype=jnp.int32)
            wanted = (n_free >= R) | (~jnp.any(c.state.live) & (n_free > 0))
            return wanted & ((k == 0) | (c.next < jnp.minimum(n_real, B)))

        return jax.lax.while_loop(more, lambda x: (x[0] + 1, refill(x[1])), (0, c))[1]

    def body(c: _Queue) -> _Queue:
        c = refills(c)
        state = c.state
        if rolled and unroll > 1:
            # One traced step run ``unroll`` times: a loop whose trip count XLA knows.
            state = jax.lax.fori_loop(0, unroll, lambda _, st: step(st, c.lane), state)
        else:
            for _ in range(unroll):  # steps of ended lanes change nothing
                state = step(state, c.lane)
        # The iteration's states are made before the next refill's test reads them: on
        # an accelerator XLA then keeps the last step's work out of the fusions after it
        # (an H200, 10 000 scenes: the three intent modes 3.231 -> 3.092 s, compile
        # 170 -> 136 s; every user setting 1.179 -> 1.163 s). A barrier after every
        # step was slower (shacc_ho 1.609 -> 1.887 s). XLA's CPU backend drops it.
        return c._replace(state=jax.lax.optimization_barrier(state))

    # Every slot empty (not live, no lane): the first iteration's refills fill them.
    first = jnp.arange(B, dtype=jnp.int32)
    lane, state = jax.tree.map(lambda a: jnp.zeros((*a.shape[:-1], B), a.dtype), shapes)
    state = state._replace(live=jnp.zeros(B, bool))
    init = _Queue(lane, state, jnp.full(B, -1, jnp.int32), jnp.zeros((), jnp.int32), result)
    end = jax.lax.while_loop(lambda c: jnp.any(c.state.live) | (c.next < n_real), body, init)
    return write(end.result, end.slot, end.lane, end.state, first, end.slot >= 0)
