"""The CPU pfjax runs on: its identity and vector extensions, from ``/proc/cpuinfo`` (Linux)."""

from __future__ import annotations

CPUINFO = "/proc/cpuinfo"
#: The vector extensions that decide XLA's CPU code (recorded by ``pfjax bench``; part of a
#: calibration's CPU identity, :mod:`pfjax.numerics.calibration`).
VECTOR_FLAGS = frozenset({"avx", "avx2", "fma", "avx512f", "avx512dq", "avx512vl", "avx512bw", "sse4_2"})


def cpu_info(cpuinfo: str = CPUINFO) -> dict:
    """The first CPU's ``vendor_id``, ``model name``, ``cpu family``, ``model`` and ``flags`` from ``/proc/cpuinfo``
    (``{}`` where that file does not exist, e.g. macOS, or cannot be read). The family tells CPU
    generations apart where the model name does not (a VM's "AMD EPYC": 25 is Zen 3/4, 26 Zen 5)."""
    out = {}
    try:
        with open(cpuinfo) as f:
            for line in f:
                if not line.strip():
                    break  # the first processor's block ends here
                key, _, value = line.partition(":")
                key = key.strip()
                if key in ("vendor_id", "model name", "cpu family", "model", "flags"):
                    out[key] = value.strip()
    except OSError:
        pass
    return out


def has_avx512(cpuinfo: str = CPUINFO) -> bool:
    """Whether the CPU has AVX-512 Foundation (``avx512f`` among the flags of ``/proc/cpuinfo``;
    False where that file does not exist or cannot be read)."""
    return "avx512f" in cpu_info(cpuinfo).get("flags", "").split()


def is_intel(cpuinfo: str = CPUINFO) -> bool:
    """Whether the CPU is Intel's (``vendor_id`` GenuineIntel), which some of pfjax's CPU rules tell
    apart (:func:`pfjax.sim.sharding.block_bytes_rule`, :func:`pfjax.numerics.elementary.sincos_sharing_rule`)."""
    return cpu_info(cpuinfo).get("vendor_id") == "GenuineIntel"
