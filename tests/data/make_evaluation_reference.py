"""Writes ``evaluation_reference.npz``: every rollout of the shipped scenes, the extra
scene and 16 random scenes of the generator in the three modes (collisions off; the
shipped scenes again with collision checks on, and with an imperfect user), with the
processor, the machine and the versions it was made with.

    JAX_PLATFORMS=cpu python tests/data/make_evaluation_reference.py

tests/test_reference_answers.py holds the evaluation to it as the reference promises
(docs/reference/outputs.md, "Reproducibility"): discrete answers exactly, numbers
within the stated tolerances, on any processor and any supported JAX. Record again only
when the arithmetic changes on purpose, and then check the new recording against the
old one under those tolerances first (:func:`compare` with ``--against``): a recording
made from the code under test, unchecked, tests nothing.
"""

from __future__ import annotations

import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

OUT = Path(__file__).with_name("evaluation_reference.npz")
RANDOM = 16
FIELDS = ("outcome", "activated", "step", "meta_steps", "point", "path_length", "delta_R",
          "orientation", "assist")
# A user with the stepped users' imperfections (the stepped kernel): a wandering hand,
# a tremor and a change of mind in three approaches of ten; the joystick is held to the
# NumPy Automaton in test_user_models.
IMPERFECT = {"user_noise": 0.2, "user_noise_tau": 0.5, "user_tremor": 0.01,
             "user_switch": 0.3}


def batches():
    """(name, precomputed scenes) of each recorded batch, the same every time."""
    from geometry_precompute import (
        extra_scene_paths,
        load_scene,
        precompute,
        random_scene,
        shipped_scene_paths,
    )

    files = [load_scene(p) for p in shipped_scene_paths() + extra_scene_paths()]
    yield "files", [precompute(s) for s in files]
    yield "files_collision", [precompute(s, {"collision": "on"}) for s in files[:12]]
    yield "random", [precompute(random_scene(3000 + i, "uniform" if i % 2 else "gaussian",
                                             2, 12, "paper")) for i in range(RANDOM)]
    yield "files_user", [precompute(s, IMPERFECT) for s in files[:6]]


def processor() -> str:
    """The processor's model name (Linux), else what the platform module says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def made_with() -> dict[str, str]:
    """Where and with what a recording is made: processor, machine, C library, Python
    and the numeric packages' versions."""
    import jax
    import jaxlib

    return {"processor": processor(), "machine": platform.machine(),
            "libc": " ".join(platform.libc_ver()), "python": platform.python_version(),
            "jax": jax.__version__, "jaxlib": jaxlib.__version__, "numpy": np.__version__,
            "backend": jax.default_backend()}


def evaluate_all() -> dict[str, np.ndarray]:
    """Every recorded array of every batch, from the code in this checkout."""
    from sweeps.pipeline import evaluate_results

    arrays = {}
    for name, results in batches():
        ev = evaluate_results(results, ("baseline", "shrinking", "shacc"))
        for f in FIELDS:
            arrays[f"{name}/{f}"] = np.asarray(getattr(ev.evaluation.rollouts, f))
        arrays[f"{name}/u_scene"] = np.asarray(ev.evaluation.metrics.u_scene)
        arrays[f"{name}/delta_R_mean"] = np.asarray(ev.evaluation.metrics.delta_R_mean)
    return arrays


# What the reference promises across processors and JAX versions (docs/reference/
# outputs.md, "Reproducibility"): these fields exactly, NaN where the recording has NaN,
# and every other number within its absolute tolerance (orientations up to sign).
EXACT = ("outcome", "activated", "step", "meta_steps", "assist", "u_scene")
TOLERANCE = {"point": 1e-6, "path_length": 1e-6, "orientation": 1e-5, "delta_R": 1e-5,
             "delta_R_mean": 1e-5}


def difference(field: str, got: np.ndarray, want: np.ndarray) -> str | None:
    """Why ``got`` breaks the promise for ``field`` against ``want``, None where it keeps
    it."""
    if got.shape != want.shape or got.dtype != want.dtype:
        return f"shape or dtype {got.shape} {got.dtype}, recorded {want.shape} {want.dtype}"
    if field in EXACT:
        bad = int(np.sum(got != want))
        return f"{bad} of {got.size} differ" if bad else None
    nan = np.isnan(want)
    if not np.array_equal(nan, np.isnan(got)):
        return f"NaN at other places ({int(np.sum(nan != np.isnan(got)))})"
    if field == "orientation":  # q and -q are the same rotation
        flip = np.sum(got * want, axis=-1, keepdims=True) < 0
        got = np.where(flip, -got, got)
    err = np.abs(np.where(nan, 0.0, got.astype(np.float64) - want.astype(np.float64)))
    worst = float(err.max()) if err.size else 0.0
    if worst > TOLERANCE[field]:
        return (f"{int(np.sum(err > TOLERANCE[field]))} of {got.size} beyond "
                f"{TOLERANCE[field]:g} (at most {worst:.3g})")
    return None


def compare(got, recorded) -> list[str]:
    """Every "batch/field: why" where the arrays ``got`` break the promise against the
    ``recorded`` ones (both mappings of the recording's keys)."""
    out = []
    for key in recorded:
        if key.startswith("made_with/"):
            continue
        why = difference(key.split("/", 1)[1], np.asarray(got[key]), np.asarray(recorded[key]))
        if why:
            out.append(f"{key}: {why}")
    return out


def main() -> None:
    from shacc_jax import configure_runtime

    configure_runtime()
    arrays = evaluate_all()
    if "--against" in sys.argv:  # the recording this one replaces
        old = np.load(sys.argv[sys.argv.index("--against") + 1])
        broken = compare(arrays, {k: old[k] for k in old.files if k in arrays})
        if broken:
            sys.exit("not written: against the old recording\n" + "\n".join(broken))
    # "-dirty": made from uncommitted code (that of the commit that adds the recording).
    commit = subprocess.run(["git", "describe", "--always", "--dirty", "--abbrev=12"],
                            capture_output=True, text=True,
                            cwd=Path(__file__).parent).stdout.strip()
    meta = {"commit": commit, **made_with()}
    np.savez_compressed(OUT, **{f"made_with/{k}": np.array(v) for k, v in meta.items()},
                        **arrays)
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes): {meta}", file=sys.stderr)


if __name__ == "__main__":
    main()
