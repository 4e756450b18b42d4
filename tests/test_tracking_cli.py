"""``pfjax track`` contract: one strict-JSON object with the documented keys, forward and backward
convergence on a line, Lemma 8.1's bound reported, bad flags -> one line on stderr and exit code 2."""

from __future__ import annotations

import json

import pytest

from pfjax.cli import main

KEYS = {
    "converged",
    "final_error_norm",
    "final_phi_minus_pgamma",
    "max_abs_gamma_deg",
    "status",
    "phi_converged",
    "inside_lemma_bound",
    "lemma_p_bound",
    "lemma_consistent",
}
FAST = ["--horizon", "12", "--dt", "0.02"]


def run(capsys, *args):
    rc = main(["track", *args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.slow  # the first case compiles the simulation (~10 s here); the others reuse it
@pytest.mark.parametrize(
    "mode,leader",
    [
        ("forward", "line"),
        ("backward", "line"),
        ("forward", "circle"),
        ("backward", "sine"),
        ("forward", "lane-change"),
    ],
)
def test_track_json(capsys, mode, leader):
    s = "1" if mode == "forward" else "-1"
    rc, out, err = run(
        capsys, "--mode", mode, "--p", s, "--l", s, "--gamma-max-deg", "30", "--leader", leader, *FAST, "--json"
    )
    assert rc == 0 and err == ""
    assert out.count("\n") == 1 and "NaN" not in out and "Infinity" not in out
    d = json.loads(out)
    assert set(d) >= KEYS
    assert d["status"] == "ok" and d["lemma_p_bound"] == pytest.approx(3.0) and d["inside_lemma_bound"]
    assert d["converged"] and d["final_error_norm"] < 1e-2 and abs(d["final_phi_minus_pgamma"]) < 2e-2
    assert 0 < d["max_abs_gamma_deg"] <= 30 + 1e-9


@pytest.mark.parametrize(
    "args,flag",
    [
        (["--p", "0"], "--p"),
        (["--l", "0"], "--l"),
        (["--gamma-max-deg", "90"], "--gamma-max-deg"),
        (["--gamma-max-deg", "-3"], "--gamma-max-deg"),
        (["--leader", "spiral"], "--leader"),
        (["--mode", "sideways"], "--mode"),
        (["--dt", "0"], "--dt"),
        (["--stop-and-go", "1.5"], "--stop-and-go"),
        (["--p", "nan"], "--p"),
        (["--wheelbase", "0"], "--wheelbase"),
        (["--horizon", "-1"], "--horizon"),
    ],
)
def test_track_bad_flags(capsys, args, flag):
    with pytest.raises(SystemExit) as e:  # argparse choices exit directly; value checks return 2
        raise SystemExit(main(["track", *args, "--json"]))
    out, err = capsys.readouterr()
    assert e.value.code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("pfjax track: error:") and flag in err
