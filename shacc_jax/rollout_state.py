"""What a stepped rollout carries: its constants (:class:`Lane`), its state
(:class:`State`), a step's move before its check (:class:`Move`), a full check's
answers (:class:`Check`) and, in the intent modes, the next step's position assistance
(:class:`Assist`). The parts of a step (``user_models``, ``activation``,
``assistance``) read and make these; the scheduler (``lanes.run_queue``) moves them
between slots. Per-lane arrays keep the lane axis last."""

from __future__ import annotations

from typing import NamedTuple

from jaxtyping import Array

from .streams import RolloutDraws
from .types import Params
from .vec3 import V3


class Lane(NamedTuple):
    """A lane's constants: its scene, task and settings, the start pose, the random
    numbers drawn once, its task's space (kind, centre, quaternion, dims, the cone's
    trigonometry: the rotation matrix is made where used, which reads fewer numbers a
    step than a stored one; the trigonometry costs more to recompute on a CPU) and aim
    point, the perfect user's path (closest point, direction, length; the rest of
    ``automaton.Path`` is p0 and numbers of the settings); for a change of mind the
    task headed for first (``decoy``: the task itself where the rollout drew none), its
    space and aim point, and the distance from the start to that space; the wandering
    hand's coefficients (w_{k+1} = ou_a w_k + ou_b xi_k) and the steps a mode switch
    costs. Every step reads them all: the move is bound by memory, so nothing is
    stored twice."""

    scene: Array
    target: Array
    x: Params
    p0: Array
    r0: Array
    real: Array
    perfect: Array
    step_key: Array
    once: RolloutDraws
    own: tuple[Array, Array, Array, Array, Array]
    aim: Array
    c0: Array
    u: Array
    length: Array
    decoy: Array
    decoy_own: tuple[Array, Array, Array, Array, Array]
    decoy_aim: Array
    ou_a: Array
    ou_b: Array
    switch_steps: Array
    # Intent inference (``assistance.posterior``): V_j(p_0), the distance from the
    # gripper's start to each task's space (T,); None outside the intent modes.
    v0: Array | None = None


class Move(NamedTuple):
    """A step's move, before its check: the step count, the commanded and gripper
    positions, the displacement, the path length, the gripper's path since the last
    full check, and the user's state after the step (the wandering hand's vector, the
    joystick's mode and pause, whether it heads for its own task)."""

    k: Array
    q: V3
    p: V3
    delta: V3
    travelled: Array
    moved: Array
    w: V3
    mode: Array | None
    pause: Array | None
    turned: Array | None


class Assist(NamedTuple):
    """The intent modes' position assistance for a lane's next step, from the posterior
    at the gripper (``assistance.position_assistance``): the step is ``(1 - share)
    user + pull`` where ``on``, else the user's."""

    share: Array
    pull: V3
    on: Array


class Check(NamedTuple):
    """A full check's answers at the gripper: its position (the entry point under the
    swept check), the path length, ended (activated or collided), the outcome code and
    activated task should it have ended (``automaton.outcome_codes``; a collision's
    code and -1), R after the meta skill's turn, whether the step counts as a meta
    step, the clearance."""

    p: Array
    travelled: Array
    done: Array
    code: Array
    activated: Array
    r: Array
    counted: Array
    clear: Array
    kind: Array | None = None  # the intent modes: the step's assistance (ASSISTANCE index)
    assist: Assist | None = None  # the intent modes: the next step's position assistance


class State(NamedTuple):
    """A lane's dynamic state, what each step changes."""

    k: Array          # steps taken
    q: V3             # commanded position
    p: V3             # gripper position
    w: V3             # the wandering hand's rotation vector w_k, rad
    # The joystick's and the change of mind's state: None where no lane of the program
    # has them (Layout.joystick, Layout.switching), so that a step carries nothing more.
    mode: Array | None    # the joystick's mode: -1 not chosen yet, 0 horizontal, 1 vertical
    pause: Array | None   # steps of a mode switch still to wait, without motion
    turned: Array | None  # heading for its own task (a change of mind is over, or none)
    d0: Array | None      # the distance from the start to the first-headed task's space, m
    r: Array          # orientation (4,)
    meta_steps: Array
    travelled: Array  # path length of the commanded position, m
    done: Array       # activated or collided
    code: Array       # the outcome code where done (a check's answer, not the T sdfs:
    activated: Array  # writing those back was a tenth of a step's time on a GPU)
    clear: Array      # the clearance found at the last full check
    moved: Array      # the gripper's path since, m
    live: Array       # still stepping
    # The intent modes: steps under assistance towards the intended task and towards
    # another (None elsewhere: the paper's modes have neither).
    correct: Array | None = None
    wrong: Array | None = None
    assist: Assist | None = None  # the next step's position assistance
