"""The JAX runtime is set up by configure_runtime(), never by an import
(shacc_jax/runtime.py): importing the three packages changes no environment variable
and no JAX setting; configure_runtime pins the CPU code generation and chooses the CPU
device count before JAX starts, respects the user's choices, and says so when it comes
too late."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from shacc_jax import determinism
from shacc_jax.runtime import cpu_devices


def _run(code: str, **env) -> dict:
    """``code`` in a fresh interpreter (CPU JAX, no device count or XLA flags of ours
    inherited); it prints one JSON object as its last line."""
    environ = {k: v for k, v in os.environ.items()
               if k not in ("JAX_NUM_CPU_DEVICES", "XLA_FLAGS")}
    out = subprocess.run([sys.executable, "-W", "always", "-c", code],
                         env={**environ, "JAX_PLATFORMS": "cpu", **env}, check=True,
                         capture_output=True, text=True, timeout=120)
    return {**json.loads(out.stdout.splitlines()[-1]), "stderr": out.stderr}


def test_importing_the_packages_changes_nothing():
    got = _run("import os, json, jax\n"
               "before = dict(os.environ), jax.config.jax_num_cpu_devices\n"
               "import shacc_jax, geometry_precompute, sweeps, sweeps.app.cli, sweeps.pipeline\n"
               "import geometry_precompute.baking, geometry_precompute.precomputing\n"
               "after = dict(os.environ), jax.config.jax_num_cpu_devices\n"
               "from jax._src import xla_bridge\n"
               "import sys, types\n"
               "print(json.dumps({'same': before == after,\n"
               "                  'started': xla_bridge.backends_are_initialized(),\n"
               "                  'plain': all(type(sys.modules[m]) is types.ModuleType\n"
               "                               for m in ('shacc_jax', 'sweeps',\n"
               "                                         'geometry_precompute')),\n"
               "                  'bake': callable(geometry_precompute.bake)}))")
    assert got["same"] and not got["started"]
    # No module object swapped, and the package's functions are not hidden by modules.
    assert got["plain"] and got["bake"]


@pytest.mark.skipif(os.uname().machine not in determinism.X86_64, reason="x86-64's pin")
def test_configure_runtime_pins_the_code_generation_and_splits_the_cpu():
    code = ("import json, os, jax, shacc_jax\n"
            "r = shacc_jax.configure_runtime()\n"
            "assert shacc_jax.configure_runtime() is r  # once\n"
            "print(json.dumps({'flags': os.environ.get('XLA_FLAGS', ''),\n"
            "                  'devices': len(jax.devices('cpu')), 'pinned': r.pinned,\n"
            "                  'late': r.late}))")
    got = _run(code)
    assert got["flags"] == determinism.FLAG and got["pinned"] and not got["late"]
    assert got["devices"] == cpu_devices()
    # The user's choices win: a device count, and an ISA of their own (then unpinned).
    assert _run(code, JAX_NUM_CPU_DEVICES="3")["devices"] == 3
    own = _run(code, XLA_FLAGS="--xla_cpu_max_isa=AVX2")
    assert own["flags"] == "--xla_cpu_max_isa=AVX2" and not own["pinned"]


def test_configure_runtime_after_jax_started_says_so():
    got = _run("import json, jax\n"
               "jax.devices()\n"
               "import shacc_jax\n"
               "r = shacc_jax.configure_runtime()\n"
               "print(json.dumps({'late': r.late, 'devices': len(jax.devices('cpu'))}))")
    assert got["late"] and got["devices"] == 1
    if os.uname().machine in determinism.X86_64:
        assert "JAX started before shacc_jax.configure_runtime()" in got["stderr"]
