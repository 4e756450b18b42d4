"""One home per tracking setting: the defaults of a run (step, horizon, window, tolerances, band, gain,
wheelbase) are ``TrackConfig``'s, ``FocusGains.k`` and ``FollowerParams.a``, read by the study's
``[sim]`` schema, :func:`pfjax.tracking.run` and ``pfjax track``; the tracker's status codes 0-3 are
:class:`pfjax.sim.status.Status`'s; the Frenet singularity's threshold is
:data:`pfjax.sim.status.SINGULAR_TOL`, which :func:`pfjax.sim.status.classify` reads and the loop's
status table names.

Identity (``is``) tells a value read from its home from an equal literal written again: CPython
keeps one float object per literal and module, so two ``30.0`` written in two modules are two
objects."""

from __future__ import annotations

import inspect
import re

import jax.numpy as jnp
import pytest

from pfjax.cli import build_parser
from pfjax.cli import track as cli_track
from pfjax.sim import loop, status
from pfjax.sim.status import SINGULAR_TOL, Status, classify
from pfjax.tracking import api
from pfjax.tracking.controller import FocusGains
from pfjax.tracking.model import FollowerParams
from pfjax.tracking.simulate import TrackConfig, TrackStatus
from pfjax.tracking.study_config import TrackSim

#: each tracking default and its one home
HOMES = {
    "dt": TrackConfig.dt,
    "horizon": TrackConfig.horizon,
    "window": TrackConfig.window,
    "tol_z": TrackConfig.tol_z,
    "tol_phi": TrackConfig.tol_phi,
    "band": TrackConfig.band,
    "k": FocusGains._field_defaults["k"],
    "a": FollowerParams._field_defaults["a"],
}


@pytest.mark.parametrize("key", sorted(HOMES))
def test_the_study_schema_reads_its_defaults_from_the_run_settings(key):
    assert TrackSim.model_fields[key].default is HOMES[key]


@pytest.mark.parametrize("key", ["horizon", "dt", "a", "k"])
def test_run_and_pfjax_track_read_their_defaults_from_the_run_settings(key):
    assert inspect.signature(api.run).parameters[key].default is HOMES[key]
    parser = build_parser()
    track = parser._subparsers._group_actions[0].choices["track"]  # type: ignore[union-attr]
    dest = {"a": "wheelbase"}.get(key, key)
    assert track.get_default(dest) is HOMES[key]


def test_every_pfjax_track_default_is_runs():
    """Each flag's default, and the one its help prints, is :func:`pfjax.tracking.run`'s."""
    parser = build_parser()
    track = parser._subparsers._group_actions[0].choices["track"]  # type: ignore[union-attr]
    dest = {"a": "wheelbase"}
    for name, q in inspect.signature(api.run).parameters.items():
        assert track.get_default(dest.get(name, name)) == q.default, name
    text = " ".join(track.format_help().split())
    assert f"horizon, s (default {TrackConfig.horizon:g})" in text
    assert f"step, s (default {TrackConfig.dt:g})" in text
    assert f"wheelbase, m (default {HOMES['a']:g})" in text
    assert f"error decay rate, 1/s (default {HOMES['k']:g})" in text
    assert cli_track.DEFAULTS["horizon"] is TrackConfig.horizon


def test_the_trackers_shared_status_codes_are_the_sims():
    """TrackStatus is Status's codes 0-3 by name, each value read from that member of Status (no
    integer written again in its class body)."""
    assert [s.name for s in TrackStatus] == [s.name for s in Status][: len(TrackStatus)]
    for s in TrackStatus:
        assert s.value == Status[s.name].value and s == Status[s.name]
    body = inspect.getsource(TrackStatus).split('"""')[-1]
    assert re.search(r"=\s*\d", body) is None, body


def test_classify_reads_the_singular_threshold(monkeypatch):
    """``1 - kappa d <= SINGULAR_TOL`` is singular, one above it is ok; the threshold is the named
    constant, read when classify runs."""
    ok = lambda v: int(classify(jnp.bool_(True), jnp.float64(0.0), jnp.float64(v), jnp.bool_(False), 10.0))
    assert SINGULAR_TOL == 1e-6
    assert ok(SINGULAR_TOL) == Status.SINGULAR and ok(2 * SINGULAR_TOL) == Status.OK
    monkeypatch.setattr(status, "SINGULAR_TOL", 0.5)
    assert ok(0.3) == Status.SINGULAR


def test_the_singular_threshold_is_written_once():
    """The loop's status table names the constant; the number is written only where it is defined."""
    assert "1 - kappa d <= SINGULAR_TOL" in (loop.__doc__ or "")
    assert "1e-6" not in (loop.__doc__ or "")
    assert inspect.getsource(status).count("1e-6") == 1
