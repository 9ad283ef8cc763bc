"""Issue 40: run directories, listeners, signals and bad input at every entry point.

- `orchestrator run --out`: refused if not empty or another user's; default names unique.
- No plain listener on an unspecified address, however spelt (world and relay router).
- SIGTERM and SIGHUP are handled like SIGINT by the orchestrator and every process.
- Bad values at `orchestrator ...`, `python -m world`, `python -m agent` and
  `python -m world.router` are one line and exit 2 (BAD_INPUT), never a traceback or exit 1;
  scenario files are capped before parsing and refuse YAML aliases.

The refusals of the real world and relay processes: tests/system/test_bad_input.py.
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agent import flags
from agent.process import STOP_SIGNALS, ExitCode, interrupt_on_stop_signals, stop_on_signals
from agent.security import RunCA
from orchestrator.cli import build_parser, main
from tests.examples import examples
from world.scenario_file import MAX_SCENARIO_BYTES, ScenarioError, load_scenario

ROOT = Path(__file__).resolve().parents[2]
SETUP_D = ROOT / "orchestrator" / "setups" / "setup_d.yaml"
SMALL = Path(__file__).parent / "data" / "crossing_6m.yaml"
"""Two robots crossing, 6 m each: a short whole run (tests/integration/test_cli.py)."""
EXIT_TABLE = {int(c) for c in ExitCode}


def one_line_error(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


# --- run directories (item 1) -----------------------------------------------------------------


def test_a_non_empty_out_is_refused_in_one_line(tmp_path, capsys):
    out = tmp_path / "RUN"
    (out / "tls").mkdir(parents=True)
    assert main(["run", "setup_a", "--mode", "lockstep", "--out", str(out)]) == 2
    assert "not empty" in one_line_error(capsys.readouterr().err)
    assert [p.name for p in out.iterdir()] == ["tls"]


def test_another_users_out_is_refused(tmp_path, capsys, monkeypatch):
    out = tmp_path / "RUN"
    out.mkdir()
    monkeypatch.setattr(os, "geteuid", lambda: out.stat().st_uid + 1)
    assert main(["run", "setup_a", "--mode", "lockstep", "--out", str(out)]) == 2
    assert "another user" in one_line_error(capsys.readouterr().err)


def test_an_empty_out_of_ours_is_used_and_closed_to_others(tmp_path):
    out = tmp_path / "RUN"
    out.mkdir()
    os.chmod(out, 0o777)
    assert main(["run", str(SMALL), "--mode", "lockstep", "--quiet", "--out", str(out)]) == 0
    assert out.stat().st_mode & 0o777 == 0o700
    assert (out / "metrics.json").is_file() and (out / "run.json").is_file()


def test_two_runs_of_one_second_get_two_directories(tmp_path, monkeypatch):
    from orchestrator.cli import run

    monkeypatch.chdir(tmp_path)  # default run directories go under ./runs
    stopped = run.default_run_name  # the clock stopped at one second
    monkeypatch.setattr(run, "default_run_name", lambda *a: stopped(*a)[:-15] + "20260101-000000")
    for _ in range(2):
        assert main(["run", str(SMALL), "--mode", "lockstep", "--quiet"]) == 0
    made = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert made == ["crossing_6m-eifp-mpc-0-20260101-000000",
                    "crossing_6m-eifp-mpc-0-20260101-000000-2"]
    for name in made:
        assert json.loads((tmp_path / "runs" / name / "run.json").read_text())["status"] \
            == "complete"


def test_a_paper_profile_run_says_so_in_its_name_header_and_plot_title(tmp_path, monkeypatch,
                                                                       capsys):
    """Issue 41's small item: a ``--profile paper`` run is told from a default one."""
    from orchestrator.analysis import plots
    from orchestrator.cli import run
    from orchestrator.experiments.families import resolve

    titles: list[str] = []
    real_save = plots.save_figure

    def save(fig, path, dpi):
        titles.extend(ax.get_title() for ax in fig.axes if ax.get_title())
        return real_save(fig, path, dpi)

    monkeypatch.setattr(plots, "save_figure", save)
    monkeypatch.chdir(tmp_path)  # default run directories go under ./runs
    main(["run", str(SMALL), "--mode", "lockstep", "--profile", "paper"])
    (made,) = (tmp_path / "runs").iterdir()
    assert made.name.startswith("crossing_6m-eifp-mpc-paper-0-")
    assert "crossing_6m eifp-mpc (paper profile) lockstep" in capsys.readouterr().out
    assert len(titles) == 1 and "(paper profile)" in titles[0]
    default = resolve("setup_a")  # and a default run says nothing of the kind
    assert "-paper" not in run.default_run_name(default, "eifp-mpc", 0)
    assert "paper" not in run.run_label(default, "eifp-mpc", "lockstep")
    assert plots.profile_note(default) == ""


# --- listeners (item 4) -----------------------------------------------------------------------

EVERYWHERE = ["tcp/0.0.0.0:7447", "tcp/[::]:7447", "tcp/[::0]:7447", "tcp/0:7447",
              "tcp/[0:0:0:0:0:0:0:0]:7447", "tcp/0x0:7447", "tcp/0.0:7447",
              "tcp/[::ffff:0.0.0.0]:7447"]


@pytest.mark.parametrize("endpoint", EVERYWHERE)
def test_every_spelling_of_every_interface_is_found(endpoint):
    assert flags.every_interface(endpoint)


@pytest.mark.parametrize("endpoint", ["tcp/127.0.0.1:7447", "tcp/[::1]:7447",
                                      "tcp/localhost:7447", "tls/127.0.0.2:1"])
def test_one_address_is_not_every_interface(endpoint):
    assert not flags.every_interface(endpoint)


@pytest.mark.parametrize("endpoint", EVERYWHERE)
def test_world_and_router_refuse_a_plain_listener_on_every_interface(endpoint, tmp_path):
    from world.node import parse_args as world_args
    from world.node import world_settings
    from world.router import parse_args as router_args
    from world.router import router_settings
    from world.scenario_file import load_scenario as load

    options = world_args(["--run", "r", "--scenario", str(SETUP_D), "--listen", endpoint])
    with pytest.raises(flags.FlagError, match="every interface only with --tls") as world:
        world_settings(options, load(SETUP_D))
    relay = router_args(["--run", "r", "--name", "b", "--robots", "1", "--listen", endpoint,
                         "--connect", "tcp/127.0.0.1:7447"])
    with pytest.raises(flags.FlagError, match="every interface only with --tls") as router:
        router_settings(relay)
    assert world.value.flag == router.value.flag == "--listen"


# --- signals (item 5) -------------------------------------------------------------------------


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_end_a_run_as_interrupted_with_partial_metrics(tmp_path, monkeypatch,
                                                                          signum):
    from orchestrator.experiments import lockstep

    real = lockstep.run_lockstep

    def signalled(scenario, out_dir, *, on_progress=None, **kw):
        sent = []

        def progress(p):
            if p.sim_t_s >= 3.0 and not sent:
                sent.append(signum)
                os.kill(os.getpid(), signum)  # as kill, systemd or Docker would
        return real(scenario, out_dir, on_progress=progress, **kw)

    monkeypatch.setattr(lockstep, "run_lockstep", signalled)
    before = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    out = tmp_path / "cut"
    assert main(["run", "setup_a", "--mode", "lockstep", "--quiet", "--out", str(out)]) \
        == ExitCode.INTERRUPTED
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and info["exit_code"] == ExitCode.INTERRUPTED
    assert json.loads((out / "metrics.json").read_text())["partial"] is True
    assert {s: signal.getsignal(s) for s in STOP_SIGNALS} == before  # handlers restored


def test_every_process_stops_cleanly_on_each_stop_signal():
    assert set(STOP_SIGNALS) == {signal.SIGTERM, signal.SIGINT, signal.SIGHUP}
    for signum in STOP_SIGNALS:
        with stop_on_signals() as stop:
            os.kill(os.getpid(), signum)
            deadline = time.monotonic() + 5.0
            while not stop and time.monotonic() < deadline:
                signal.sigtimedwait([], 0.01)  # let the handler run
        assert stop.signum == signum
    with interrupt_on_stop_signals(), pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGHUP)
        signal.sigtimedwait([], 1.0)


# --- bad input (item 6) -----------------------------------------------------------------------


def test_a_negative_seed_is_a_usage_error(capsys):
    assert main(["run", "setup_a", "--mode", "lockstep", "--seed", "-1"]) == 2
    assert "--seed" in one_line_error(capsys.readouterr().err)


def write_ca(d: Path, key) -> Path:
    d.mkdir()
    ca = RunCA("site")
    (d / "ca.pem").write_bytes(ca.cert_pem)
    (d / "ca.key").write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                                 serialization.PrivateFormat.PKCS8,
                                                 serialization.NoEncryption()))
    return d


@pytest.mark.parametrize("case", ["not-pem", "rsa", "dir-as-file"])
def test_an_unusable_tls_ca_is_one_line_exit_2(tmp_path, capsys, case):
    if case == "rsa":
        ca = write_ca(tmp_path / "ca", rsa.generate_private_key(public_exponent=65537,
                                                                key_size=2048))
    else:
        ca = tmp_path / "ca"
        ca.mkdir()
        (ca / "ca.pem").write_text("not a certificate")
        if case == "dir-as-file":
            (ca / "ca.key").mkdir()
        else:
            (ca / "ca.key").write_text("not a key")
    out = tmp_path / "out"
    assert main(["run", "setup_a", "--tls-ca", str(ca), "--out", str(out)]) == 2
    assert "--tls-ca" in one_line_error(capsys.readouterr().err)
    assert not out.exists()  # refused before anything was made


def test_a_yaml_alias_bomb_is_refused_at_once(tmp_path):
    bomb = tmp_path / "bomb.yaml"
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    lines.append("name: *a8")
    bomb.write_text("\n".join(lines) + "\n")
    assert bomb.stat().st_size < 1000
    t0 = time.monotonic()
    with pytest.raises(ScenarioError, match="aliases") as err:
        load_scenario(bomb)
    assert time.monotonic() - t0 < 1.0 and len(str(err.value)) < 300


def test_a_scenario_larger_than_the_cap_is_refused_before_parsing(tmp_path):
    big = tmp_path / "big.yaml"
    with open(big, "w") as f:
        f.write("name: big\ntime_limit: 10\nrobots:\n")
        f.write("  - {id: 0, start: [0, 0, 0], goal: [1, 0]}\n" * (MAX_SCENARIO_BYTES // 40))
    t0 = time.monotonic()
    with pytest.raises(ScenarioError, match="larger than"):
        load_scenario(big)
    assert time.monotonic() - t0 < 1.0


def test_error_messages_show_a_bounded_part_of_a_huge_value(tmp_path):
    path = tmp_path / "s.yaml"
    for huge in ("defaults: {planner: " + "x" * 20_000 + "}\n",
                 "defaults: {v_max: [" + ", ".join(["[1, 2, 3]"] * 5_000) + "]}\n",
                 "x" * 20_000 + ": 1\n"):
        path.write_text(f"name: s\ntime_limit: 10\n{huge}"
                        "robots:\n  - {id: 0, start: [0, 0, 0], goal: [1, 0]}\n")
        with pytest.raises(ScenarioError) as err:
            load_scenario(path)
        assert len(str(err.value)) < 400, str(err.value)[:500]


@pytest.mark.parametrize("argv", [
    ["-m", "world", "--run", "r", "--scenario", str(SETUP_D), "--listen", "garbage"],
    ["-m", "agent", "--run", "r", "--id", "1", "--connect", "garbage"],
])
def test_garbage_endpoints_are_usage_errors(argv, capsys):
    from agent.startup import parse_args as agent_args
    from world.node import parse_args as world_args

    parse = world_args if argv[1] == "world" else agent_args
    with pytest.raises(SystemExit) as exc:
        parse(argv[2:])
    assert exc.value.code == ExitCode.BAD_INPUT
    assert "expected tcp/HOST:PORT" in one_line_error(capsys.readouterr().err)


# --- every entry point's parser, driven with generated values ---------------------------------

def _parsers():
    from agent.fleet import build_parser as fleet_parser
    from agent.startup import parse_args as agent_args
    from world.node import parse_args as world_args
    from world.router import parse_args as router_args

    return {
        "world": (world_args, ["--run", "r", "--scenario", str(SETUP_D)]),
        "agent": (agent_args, ["--run", "r", "--id", "0", "--connect", "tcp/127.0.0.1:1"]),
        "router": (router_args, ["--run", "r", "--name", "b", "--robots", "1", "--listen",
                                 "tcp/127.0.0.1:1", "--connect", "tcp/127.0.0.1:2"]),
        "fleet": (fleet_parser().parse_args, ["--run", "r", "--ids", "0,1", "--connect",
                                              "tcp/127.0.0.1:1", "--log-dir", "/nonexistent"]),
    }


def _options(parser) -> list[str]:
    """The flags of `parser` that take a value."""
    return sorted(o for a in parser._actions if a.option_strings and a.nargs != 0
                  for o in a.option_strings if o.startswith("--"))


VALUES = st.one_of(
    st.text(max_size=40), st.integers().map(str), st.floats().map(repr),
    st.sampled_from(["-1", "0", "nan", "inf", "-inf", "1e999", "tcp/0:1", "tcp/[::0]:1",
                     "garbage", "", "a" * 5000, "tcp/h:99999", "8-1", "b=", "1,1"]))


@settings(max_examples=examples(300), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_process_parsers_give_a_value_or_one_line_exit_2(data, capsys):
    """python -m world, python -m agent, python -m world.router (and python -m agent.fleet):
    any value for any flag is parsed or refused in one line with exit 2; never a
    traceback."""
    which = data.draw(st.sampled_from(["world", "agent", "router", "fleet"]))
    parse, base = _parsers()[which]
    flag = data.draw(st.sampled_from(["--run", "--id", "--name", "--robots", "--listen",
                                      "--connect", "--rate-hz", "--time-scale", "--seed",
                                      "--fault-seed", "--drop", "--latency-ms", "--relay",
                                      "--zid", "--world-zid", "--tls", "--control-rate-hz",
                                      "--startup-timeout-s", "--wait-world-s", "--ids",
                                      "--connect-id", "--max-starting", "--cpu-tokens",
                                      "--nice"]))
    value = data.draw(VALUES)
    capsys.readouterr()
    try:
        parse([*base, f"{flag}={value}"])
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    err = capsys.readouterr().err
    assert code in (0, ExitCode.BAD_INPUT), (which, flag, value, err)
    if code:
        one_line_error(err)
    assert "Traceback" not in err


@settings(max_examples=examples(300), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_orchestrator_parser_gives_a_value_or_one_line_exit_2(data, capsys):
    """Every `orchestrator` subcommand, any value for any of its flags: parsed, or one line
    and exit 2, never a traceback; `main` maps the result into the exit table."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    name = data.draw(st.sampled_from(sorted(sub.choices)))
    flag = data.draw(st.sampled_from(_options(sub.choices[name]) or ["--help"]))
    value = data.draw(VALUES)
    capsys.readouterr()
    try:
        parser.parse_args([name, "setup_a", f"{flag}={value}"] if name in ("run", "stress")
                          else [name, f"{flag}={value}"])
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    err = capsys.readouterr().err
    assert code in EXIT_TABLE and code in (0, ExitCode.BAD_INPUT), (name, flag, value, err)
    if code:
        one_line_error(err)
    assert "Traceback" not in err
