"""System test of the docker-compose demo (Dockerfile, compose.yaml, compose.setup-g.yaml,
compose.routers.yaml).

Runs the demo for real: the world, every robot and the orchestrator in containers of their
own on a Compose network, talking only through Zenoh; and the two-host variant, robots 2-3
behind a relay router on a network of their own.

It never changes the host unasked. By default it runs against the image you built with
``docker/demo.sh --build-only`` (``EIFP_IMAGE``, default ``eifp-swarm:latest``; it tests that
image as it is, so rebuild it after changing the sources) and skips, naming that command,
when there is none. With ``EIFP_DOCKER_BUILD=1`` (``.ci/run`` sets it) it builds a throwaway
image from the sources instead, on ``EIFP_BASE_IMAGE`` if set, else ``python:3.11-slim`` or
the local base ``eifp-swarm-base:bookworm`` if either is here, else a local base it builds
with docker/build-base-image.sh (root and debootstrap needed; it installs nothing), with the
wheels downloaded into a temporary build context, never into the working tree; and at the
end it removes every image it built (the base too, unless ``EIFP_DOCKER_KEEP_BASE=1``).
The last test checks that `docker images -a` and the working tree are as they were.
Skipped, with the reason, where there is no Docker Engine or no Compose tool (or
EIFP_SKIP_DOCKER is set).

Wall time on the 2-core development machine (Docker 20.10 on fuse-overlayfs, docker-compose
1.29.2): docs/docker.md, "Tested".
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tempfile
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

from agent.process import ExitCode
from orchestrator.experiments.distributed import robot_starts

pytestmark = [pytest.mark.system, pytest.mark.docker, pytest.mark.timeout(2400)]
# With `pytest tests -n 3` (the README's test command) pyproject's `--dist loadfile` keeps this
# module's tests in order on one worker: they share the image it builds, and the last one
# checks the host. (xdist's `loadgroup` marks did not group tests under pytest 9.)

REPO = Path(__file__).resolve().parents[2]
LOCAL_BASE_IMAGE = "eifp-swarm-base:bookworm"
REGISTRY_BASE_IMAGE = "python:3.11-slim"
USER_IMAGE = os.environ.get("EIFP_IMAGE", "eifp-swarm:latest")
"""The image a user built with `BUILD_COMMAND`: what a plain `pytest tests` runs against."""
BUILD_COMMAND = "docker/demo.sh --build-only"
BUILD_ENV = "EIFP_DOCKER_BUILD"
"""Set to 1 to let the tests build (and afterwards remove) an image of their own."""
KEEP_BASE_ENV = "EIFP_DOCKER_KEEP_BASE"
"""With EIFP_DOCKER_BUILD=1: keep the local base image the tests built (as
eifp-swarm-base:bookworm, which the next run then reuses) instead of removing it; a CI
machine's choice (`.ci/run`), saving the debootstrap (1-2 min) of every later run."""
CONTEXT_FILES = ("pyproject.toml", "README.md", "Dockerfile", "eifp_wire", "agent", "world",
                 "orchestrator", "docker/entrypoint.sh")
"""What the Dockerfile copies (.dockerignore), for the temporary build context."""

DOCKER_INFO_S = 30.0
BASE_IMAGE_S = 900.0
WHEELS_S = 600.0
BUILD_S = 1200.0
UP_S = 180.0
"""Creating and starting the containers (detached)."""
RUN_S = 600.0
"""A whole setup-D run: start-up, 140 s of sim time at most, the report."""
EXEC_S = 30.0
DOWN_S = 120.0
ROBOTS_D = 4


def _run(cmd: list[str], timeout_s: float, env: dict[str, str] | None = None,
         check: bool = True, cwd: Path = REPO) -> subprocess.CompletedProcess[str]:
    try:
        proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True,
                              timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"{' '.join(cmd)} did not finish within {timeout_s:.0f} s; output:\n"
                    f"{(exc.stdout or b'')[-3000:]!r}\n{(exc.stderr or b'')[-3000:]!r}")
    if check and proc.returncode != 0:
        pytest.fail(f"{' '.join(cmd)} exited {proc.returncode}:\n{proc.stdout[-3000:]}\n"
                    f"{proc.stderr[-3000:]}")
    return proc


def _compose_command() -> list[str] | None:
    for cmd in (["docker", "compose"], ["docker-compose"]):
        if shutil.which(cmd[0]) is None:
            continue
        try:
            ok = subprocess.run([*cmd, "version"], capture_output=True, timeout=30,
                                check=False).returncode == 0
        except (OSError, subprocess.TimeoutExpired):
            ok = False
        if ok:
            return cmd
    return None


def _image_exists(image: str) -> bool:
    return subprocess.run(["docker", "image", "inspect", image], capture_output=True,
                          timeout=30, check=False).returncode == 0


def _image_id(image: str) -> str:
    return subprocess.run(["docker", "image", "inspect", "-f", "{{.Id}}", image],
                          capture_output=True, text=True, timeout=30, check=False).stdout.strip()


def _image_ids() -> set[str]:
    """Every image id on the engine, intermediate ones too (`docker images -a`)."""
    out = subprocess.run(["docker", "images", "-a", "-q", "--no-trunc"], capture_output=True,
                         text=True, timeout=60, check=False).stdout
    return set(out.split())


def _tree_state() -> dict[str, tuple[int, int]]:
    """path -> (size, mtime) of every file of the working tree, ignored ones too (`runs/`,
    `docker/wheels/`), less git's own, the venv and Python's and pytest's caches."""
    skip = {".git", ".venv", "__pycache__", ".pytest_cache", ".hypothesis", ".ruff_cache"}
    state = {}
    for root, dirs, files in os.walk(REPO):
        dirs[:] = [d for d in dirs if d not in skip]
        for name in files:
            path = Path(root) / name
            st = path.lstat()
            state[str(path.relative_to(REPO))] = (st.st_size, st.st_mtime_ns)
    return state


TREE_BEFORE = _tree_state()
"""The working tree as the docker layer found it (taken when this module is collected)."""


@dataclass
class DockerSetup:
    """How this machine runs the demo: the Compose command, the environment, what the
    tests built (removed by `cleanup`), timings."""

    compose: list[str]
    env: dict[str, str]
    image: str
    built: list[str] = field(default_factory=list)
    images_before: set[str] | None = None
    """`docker images -a` before the tests built anything (None: they build nothing)."""
    kept: list[str] = field(default_factory=list)
    """Images built and kept on purpose (`KEEP_BASE_ENV`)."""
    timings: dict[str, float] = field(default_factory=dict)

    def cleanup(self) -> None:
        """Remove every image the tests built, and the intermediate ones of their builds."""
        for image in reversed(self.built):
            subprocess.run(["docker", "rmi", "-f", image], capture_output=True, timeout=300,
                           check=False)
        self.built.clear()
        if self.images_before is not None:
            dangling = subprocess.run(
                ["docker", "images", "-q", "--no-trunc", "-f", "dangling=true"],
                capture_output=True, text=True, timeout=60, check=False).stdout.split()
            for image in set(dangling) - self.images_before:
                subprocess.run(["docker", "rmi", image], capture_output=True, timeout=300,
                               check=False)


SETUP: list[DockerSetup] = []
"""The module's `DockerSetup`, once made (the last test cleans up through it)."""


@pytest.fixture(scope="module")
def compose_command() -> list[str]:
    """`docker compose` or `docker-compose` (else skip)."""
    if os.environ.get("EIFP_SKIP_DOCKER"):
        pytest.skip("EIFP_SKIP_DOCKER is set")
    compose = _compose_command()
    if compose is None:
        pytest.skip("neither `docker compose` nor `docker-compose` works on this machine")
    return compose


def _engine_or_skip() -> None:
    if shutil.which("docker") is None:
        pytest.skip("no docker command on PATH: the demo needs a Docker Engine")
    try:
        info = subprocess.run(["docker", "info", "--format", "{{.ServerVersion}}"],
                              capture_output=True, text=True, timeout=DOCKER_INFO_S, check=False)
    except subprocess.TimeoutExpired:
        pytest.skip(f"`docker info` did not answer within {DOCKER_INFO_S:.0f} s: "
                    "no usable Docker Engine")
    if info.returncode != 0:
        reason = (info.stderr.strip().splitlines() or ["no output"])[-1]
        pytest.skip(f"no usable Docker Engine (`docker info` failed: {reason})")


def _base_image(setup: DockerSetup, tmp: Path) -> str:
    """The base to build on (see the module docstring); a local base built here is added to
    `setup.built`. Fails, saying what is missing, where there is none."""
    if os.environ.get("EIFP_BASE_IMAGE"):
        return os.environ["EIFP_BASE_IMAGE"]
    for image in (REGISTRY_BASE_IMAGE, LOCAL_BASE_IMAGE):
        if _image_exists(image):
            return image
    can_root = os.geteuid() == 0
    has_debootstrap = bool(shutil.which("debootstrap") or Path("/usr/sbin/debootstrap").exists())
    if not (can_root and has_debootstrap):
        pytest.fail(f"{BUILD_ENV}=1: no base image: set EIFP_BASE_IMAGE, or have "
                    f"{REGISTRY_BASE_IMAGE} here, or run as root with debootstrap installed "
                    "(the tests install nothing)")
    keep = os.environ.get(KEEP_BASE_ENV, "") not in ("", "0")
    tag = LOCAL_BASE_IMAGE if keep else f"eifp-swarm-base:test-{uuid.uuid4().hex[:8]}"
    env = {**os.environ, "LOCAL_BASE_IMAGE": tag, "ROOTFS_DIR": str(tmp / "rootfs")}
    (setup.kept if keep else setup.built).append(tag)
    t0 = time.monotonic()
    _run([str(REPO / "docker/build-base-image.sh")], BASE_IMAGE_S, env)
    setup.timings["base_image_s"] = time.monotonic() - t0
    return tag


def _build(setup: DockerSetup, tmp: Path) -> None:
    """Build `setup.image` from a temporary copy of the sources (and wheels, on a local
    base whose containers may not reach PyPI)."""
    base = _base_image(setup, tmp)
    context = tmp / "context"
    for name in CONTEXT_FILES:
        src, dst = REPO / name, context / name
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(src, dst)
    wheels = context / "docker" / "wheels"
    wheels.mkdir(parents=True, exist_ok=True)
    if base != REGISTRY_BASE_IMAGE:
        t0 = time.monotonic()
        _run([str(REPO / "docker/fetch-wheels.sh")], WHEELS_S,
             {**os.environ, "WHEELS_DIR": str(wheels)})
        setup.timings["wheels_s"] = time.monotonic() - t0
    setup.built.append(setup.image)
    t0 = time.monotonic()
    _run(["docker", "build", "--rm", "--force-rm", "--build-arg", f"BASE_IMAGE={base}",
          "-t", setup.image, str(context)], BUILD_S)
    setup.timings["build_s"] = time.monotonic() - t0


@pytest.fixture(scope="module")
def docker_setup(compose_command: list[str]) -> Iterator[DockerSetup]:
    """The image to run: the user's (else skip, naming the command that builds it), or, with
    EIFP_DOCKER_BUILD=1, one built here and removed at the end."""
    _engine_or_skip()
    build = os.environ.get(BUILD_ENV, "") not in ("", "0")
    image = f"eifp-swarm:test-{uuid.uuid4().hex[:8]}" if build else USER_IMAGE
    if not build and not _image_exists(image):
        pytest.skip(f"no image {image}: build it with `{BUILD_COMMAND}` (the docker layer then "
                    f"runs against it), or set {BUILD_ENV}=1 to build a throwaway image here "
                    "and remove it afterwards")
    env = {**os.environ, "EIFP_IMAGE": image}
    env.pop("COMPOSE_PROJECT_NAME", None)
    env.pop("COMPOSE_FILE", None)
    setup = DockerSetup(compose_command, env, image,
                        images_before=_image_ids() if build else None)
    SETUP.append(setup)
    try:
        if build:
            with tempfile.TemporaryDirectory(prefix="eifp-docker-build-") as tmp:
                _build(setup, Path(tmp))
        yield setup
    finally:
        setup.cleanup()


class Demo:
    """One Compose project of the demo (a unique project name and run id)."""

    def __init__(self, setup: DockerSetup, tag: str, time_scale: float = 1.0,
                 files: tuple[str, ...] = ("compose.yaml",)) -> None:
        suffix = uuid.uuid4().hex[:8]
        self.project = f"eifptest{tag}{suffix}"
        self.run_id = f"test-{tag}-{suffix}"
        self.env = {**setup.env, "RUN_ID": self.run_id, "TIME_SCALE": repr(time_scale)}
        self.base = [*setup.compose, "-p", self.project]
        for f in files:
            self.base += ["-f", f]

    def compose(self, *args: str, timeout_s: float, check: bool = True
                ) -> subprocess.CompletedProcess[str]:
        return _run([*self.base, *args], timeout_s, self.env, check=check)

    def containers(self) -> dict[str, dict]:
        """service -> `docker inspect` of its container (by Compose's labels)."""
        ids = _run(["docker", "ps", "-a", "-q", "--filter",
                    f"label=com.docker.compose.project={self.project}"], EXEC_S).stdout.split()
        if not ids:
            return {}
        found = json.loads(_run(["docker", "inspect", *ids], EXEC_S).stdout)
        out: dict[str, dict] = {}
        for c in found:
            service = c["Config"]["Labels"]["com.docker.compose.service"]
            assert service not in out, f"service {service} has more than one container"
            out[service] = c
        return out

    def container_id(self, service: str) -> str:
        containers = self.containers()
        assert service in containers, f"no container for {service}: {sorted(containers)}"
        return containers[service]["Id"]

    def logs(self, service: str) -> str:
        proc = _run(["docker", "logs", self.container_id(service)], EXEC_S)
        return proc.stdout + proc.stderr

    def read_run_file(self, name: str) -> str:
        """A file of the running run, read inside the orchestrator's container."""
        proc = _run(["docker", "exec", self.container_id("orchestrator"), "cat",
                     f"/runs/{self.run_id}/{name}"], EXEC_S, check=False)
        return proc.stdout if proc.returncode == 0 else ""

    def events(self) -> list[dict]:
        return [json.loads(line) for line in self.read_run_file("events.jsonl").splitlines()
                if line.endswith("}")]

    def wait_event(self, kind: str, deadline_s: float) -> dict:
        deadline = time.monotonic() + deadline_s
        while time.monotonic() < deadline:
            for event in self.events():
                if event.get("kind") == kind:
                    return event
            state = self.containers().get("orchestrator", {}).get("State", {})
            if state and not state.get("Running"):
                pytest.fail(f"the orchestrator exited ({state.get('ExitCode')}) before a "
                            f"{kind!r} event:\n{self.logs('orchestrator')[-3000:]}")
            time.sleep(0.5)
        pytest.fail(f"no {kind!r} event within {deadline_s:.0f} s; events: {self.events()}")

    def wait_exit(self, service: str, deadline_s: float) -> int:
        proc = _run(["docker", "wait", self.container_id(service)], deadline_s)
        return int(proc.stdout.strip())

    def copy_run(self, dest: Path) -> Path:
        """The run directory, copied out of the volume (through the stopped orchestrator)."""
        target = dest / self.run_id
        _run(["docker", "cp", f"{self.container_id('orchestrator')}:/runs/{self.run_id}",
              str(target)], EXEC_S)
        return target

    def down(self) -> None:
        self.compose("down", "--volumes", "--remove-orphans", "--timeout", "10",
                     timeout_s=DOWN_S, check=False)


@pytest.fixture
def demo_factory(docker_setup: DockerSetup) -> Iterator:
    demos: list[Demo] = []

    def make(tag: str, **kwargs: object) -> Demo:
        demo = Demo(docker_setup, tag, **kwargs)
        demos.append(demo)
        return demo

    try:
        yield make
    finally:
        for demo in demos:
            demo.down()
        leftovers = [d.project for d in demos if d.containers()]
        assert not leftovers, f"containers left behind by {leftovers}"


def robot_services(n: int) -> list[str]:
    return [f"robot-{k}" for k in range(n)]


def assert_run_files(run_dir: Path) -> None:
    for name in ("scenario.yaml", "trajectory.csv", "commands.csv", "events.jsonl",
                 "metrics.json", "report.txt", "run.json", "trajectory.png", "run.mcap"):
        path = run_dir / name
        assert path.is_file() and path.stat().st_size > 0, f"{path} missing or empty"


def test_setup_d_runs_end_to_end(docker_setup: DockerSetup, demo_factory, tmp_path: Path
                                 ) -> None:
    """`compose up` (attached, as a user runs it): every robot arrives, no contact."""
    demo = demo_factory("d")
    t0 = time.monotonic()
    up = demo.compose("up", "--no-build", timeout_s=RUN_S, check=False)
    docker_setup.timings["setup_d_up_s"] = time.monotonic() - t0
    containers = demo.containers()
    assert sorted(containers) == sorted(["certs", "world", "orchestrator",
                                         *robot_services(ROBOTS_D)])
    states = {s: c["State"] for s, c in containers.items()}
    assert all(not st["Running"] for st in states.values()), states
    assert states["orchestrator"]["ExitCode"] == 0, (
        f"orchestrator exit {states['orchestrator']['ExitCode']}:\n{up.stdout[-5000:]}")
    assert states["world"]["ExitCode"] == 0
    assert states["certs"]["ExitCode"] == 0
    # Each service holds only its own key (a volume of its own at /tls).
    for service, c in containers.items():
        if service == "certs":
            continue
        tls_mounts = [m for m in c["Mounts"] if m["Destination"] == "/tls"]
        assert len(tls_mounts) == 1, (service, c["Mounts"])
        assert tls_mounts[0]["Name"].endswith(f"_tls-{service}"), (service, tls_mounts)

    # Each robot ran in a container of its own, as its own process, and left on the end.
    robots = [containers[s] for s in robot_services(ROBOTS_D)]
    assert len({c["Id"] for c in robots}) == ROBOTS_D
    assert len({c["Config"]["Hostname"] for c in robots}) == ROBOTS_D
    for k, c in enumerate(robots):
        assert c["State"]["ExitCode"] == 0
        assert c["Config"]["Env"].count(f"ROBOT_ID={k}") == 1
        log = demo.logs(f"robot-{k}")
        assert f"robot {k} exit: reason='end (all_arrived)' code=0" in log, log[-2000:]
        for other in set(range(ROBOTS_D)) - {k}:
            assert f"robot {other}:" not in log  # no other robot's process in this container

    run_dir = demo.copy_run(tmp_path)
    assert_run_files(run_dir)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["success"] is True
    assert metrics["contacts"] == 0
    assert metrics["robots"] == ROBOTS_D and metrics["arrived"] == ROBOTS_D
    events = [json.loads(line) for line in (run_dir / "events.jsonl").read_text().splitlines()]
    joined = {e["robot"] for e in events if e["kind"] == "robot_joined"}
    assert joined == set(range(ROBOTS_D))
    end = [e for e in events if e["kind"] == "end"]
    assert len(end) == 1 and end[0]["reason"] == "all_arrived" and end[0]["contacts"] == 0
    assert not [e for e in events if e["kind"] in ("contact", "robot_lost")]
    rows = (run_dir / "trajectory.csv").read_text().splitlines()[1:]
    assert {int(r.split(",")[1]) for r in rows} == set(range(ROBOTS_D))
    run = json.loads((run_dir / "run.json").read_text())
    assert run["mode"] == "docker-compose" and run["run_id"] == demo.run_id
    # The ending as a local run records it (`orchestrator.analysis.rundir.run_ending`).
    assert (run["status"], run["exit_code"], run["end_reason"], run["lost"]) == (
        "complete", 0, "all_arrived", [])
    assert re.search(r"^end reason\s+all_arrived$", (run_dir / "report.txt").read_text(),
                     re.MULTILINE)
    assert run["zenoh"]["tls"] is True and run["zenoh"]["endpoints"] == ["tls/world:7447"]
    ready = next(e for e in events if e["kind"] == "world_ready")
    assert ready["tls"] is True and ready["endpoint"] == "tls/0.0.0.0:7447"
    assert re.search(r"^success\s+yes$", (run_dir / "report.txt").read_text(), re.MULTILINE)
    print(f"\ndocker demo timings: {docker_setup.timings}")


STOPPED_ROBOT = 2
"""Robot 2 drives from (-18, 0) to (18, 0); stopped early it sits in robot 0's lane."""
STOP_AT_SIM_S = 5.0
TIME_SCALE_STOP_CASE = 3.0
"""Sim seconds per wall second of the stopped-robot case: the run lasts until the others
have arrived (about 40 s of sim time)."""


def test_stopped_robot_container_leaves_no_contact(docker_setup: DockerSetup, demo_factory,
                                                   tmp_path: Path) -> None:
    """One robot's container is stopped mid-run: it is lost and braked, the others go around
    it, and the run ends once they have arrived (the lost robot does not hold it to its
    140 s limit), with no contact; the status says a robot was lost."""
    demo = demo_factory("stop", time_scale=TIME_SCALE_STOP_CASE)
    t0 = time.monotonic()
    demo.compose("up", "--no-build", "--detach", timeout_s=UP_S)
    start = demo.wait_event("start", UP_S + 300.0)
    # Stop the robot STOP_AT_SIM_S of sim time after the start (the start event's wall stamp).
    stop_at_wall = start["wall"] + STOP_AT_SIM_S / TIME_SCALE_STOP_CASE
    time.sleep(max(0.0, stop_at_wall - time.time()))
    _run(["docker", "stop", "--time", "10", demo.container_id(f"robot-{STOPPED_ROBOT}")], 60.0)
    status = demo.wait_exit("orchestrator", RUN_S)
    docker_setup.timings["stopped_robot_case_s"] = time.monotonic() - t0

    containers = demo.containers()
    assert all(not c["State"]["Running"] for c in containers.values())
    logs = demo.logs("orchestrator")
    # The stopped robot's process left and the world saw its token go: ROBOT_LOST.
    assert status == ExitCode.ROBOT_LOST, (
        f"orchestrator exit {status} (expected ROBOT_LOST):\n{logs[-4000:]}")
    stopped_log = demo.logs(f"robot-{STOPPED_ROBOT}")
    assert f"robot {STOPPED_ROBOT} exit: reason='signal' code=0" in stopped_log, stopped_log[-2000:]

    run_dir = demo.copy_run(tmp_path)
    assert_run_files(run_dir)
    events = [json.loads(line) for line in (run_dir / "events.jsonl").read_text().splitlines()]
    lost = [e for e in events if e["kind"] == "robot_lost"]
    assert [e["robot"] for e in lost] == [STOPPED_ROBOT]
    assert lost[0]["t"] > 0.0  # mid-run, not before the start
    assert not [e for e in events if e["kind"] == "contact"]
    end = [e for e in events if e["kind"] == "end"]
    assert len(end) == 1 and end[0]["contacts"] == 0
    assert end[0]["reason"] == "arrived_or_lost" and end[0]["lost"] == [STOPPED_ROBOT]
    assert end[0]["t"] < 140.0 - 30.0, end[0]  # well before the time limit
    others = set(range(ROBOTS_D)) - {STOPPED_ROBOT}
    assert set(end[0]["arrived"]) == others
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["contacts"] == 0 and metrics["success"] is False
    assert metrics["arrived"] == len(others)
    assert f"robots lost during the run: [{STOPPED_ROBOT}]" in (run_dir / "report.txt").read_text()
    run = json.loads((run_dir / "run.json").read_text())
    assert (run["status"], run["exit_code"], run["end_reason"], run["lost"]) == (
        "complete", ExitCode.ROBOT_LOST, "arrived_or_lost", [STOPPED_ROBOT])
    print(f"\ndocker demo timings: {docker_setup.timings}")


ROGUE_SCRIPT = r"""
import sys, time, zenoh
ok = []
for name, conf in sys_confs():
    try:
        s = zenoh.open(conf)
    except zenoh.ZError as exc:
        print(f"{name}: refused: {str(exc)[:120]}")
        continue
    sub = s.declare_subscriber("eifp/**")
    s.put(f"eifp/{sys.argv[1]}/control", b"forged")
    time.sleep(2.0)
    got = sub.try_recv()
    print(f"{name}: CONNECTED, received {got is not None}")
    ok.append(name)
    s.close()
sys.exit(1 if ok else 0)
"""
ROGUE_CONFS = r"""
def sys_confs():
    import json
    def conf(endpoint, **extra):
        c = zenoh.Config()
        for k, v in {"mode": '"client"', "scouting/multicast/enabled": "false",
                     "connect/endpoints": json.dumps([endpoint]), "connect/timeout_ms": "3000",
                     **extra}.items():
            c.insert_json5(k, v)
        return c
    yield "plain tcp", conf("tcp/world:7447")
    yield "tls without a certificate", conf(
        "tls/world:7447", **{"transport/link/tls/verify_name_on_connect": "false"})
"""


def test_a_rogue_container_without_a_certificate_cannot_connect(docker_setup: DockerSetup,
                                                                demo_factory,
                                                                tmp_path: Path) -> None:
    """A container on the demo's network, without a certificate: it cannot open a session to
    the world (plain TCP, or TLS presenting nothing), so it can neither publish nor subscribe;
    the run is not disturbed."""
    demo = demo_factory("rogue", time_scale=2.0)
    demo.compose("up", "--no-build", "--detach", timeout_s=UP_S)
    demo.wait_event("start", UP_S + 300.0)
    network = next(iter(demo.containers()["world"]["NetworkSettings"]["Networks"]))
    rogue = _run(["docker", "run", "--rm", "--network", network, "--entrypoint", "python",
                  docker_setup.image, "-c", ROGUE_CONFS + ROGUE_SCRIPT, demo.run_id], 120.0,
                 check=False)
    out = rogue.stdout + rogue.stderr
    assert rogue.returncode == 0, out[-3000:]
    assert out.count("refused") == 2, out[-3000:]
    status = demo.wait_exit("orchestrator", RUN_S)
    assert status == ExitCode.OK, demo.logs("orchestrator")[-3000:]
    run_dir = demo.copy_run(tmp_path)
    events = [json.loads(line) for line in (run_dir / "events.jsonl").read_text().splitlines()]
    assert not [e for e in events if e["kind"] in ("contact", "robot_lost")]
    end = [e for e in events if e["kind"] == "end"][0]
    assert end["reason"] == "all_arrived" and end["rejected"] == 0


TIME_SCALE_ROUTERS = 2.0
HOST_OF = {"world": "host-a", "orchestrator": "host-a", "robot-0": "host-a",
           "robot-1": "host-a", "router-b": "host-b", "robot-2": "host-b", "robot-3": "host-b"}
"""compose.routers.yaml: the "host" network of each service (world and router-b are on `wan`
too)."""
RELAY_ROGUE = r"""
import sys, time, zenoh
from agent.process import zenoh_config
from eifp_wire import RunKeys, TlsFiles, session_settings
keys = RunKeys(sys.argv[1])
tls = TlsFiles.in_dir("/tls", "robot-2")
def session(endpoint):
    return zenoh.open(zenoh_config(session_settings(
        mode="client", connect=[endpoint], connect_timeout_ms=1000, tls=tls)))
try:
    session("tls/world:7447").close()
    print("world: CONNECTED")
except zenoh.ZError:
    print("world: unreachable")
s = session("tls/router-b:7447")
others = [keys.cmd(0), keys.cmd(3), *(keys.poses_cell(k, (0, 0)) for k in range(5)), keys.control]
pubs = [s.declare_publisher(k) for k in [*others, keys.cmd(2)]]
deadline = time.monotonic() + 10.0
while not pubs[-1].matching_status.matching and time.monotonic() < deadline:
    time.sleep(0.05)
matched = pubs[-1].matching_status.matching
for _ in range(3):
    for pub in pubs:
        pub.put(b"forged")
    time.sleep(0.1)
time.sleep(1.0)
s.close()
print("sent, own key matched:", matched)
"""
"""Holds robot 2's certificate, on host B: the world is out of reach; through router-b it
puts garbage on robot 2's own command key (the world must count it: the path is open) and
on robots 0 and 3's commands, every pose slot and control (router-b must drop them)."""


def test_robots_on_two_hosts_through_routers(docker_setup: DockerSetup, demo_factory,
                                             tmp_path: Path) -> None:
    """compose.routers.yaml: robots 0-1 dial the world's router on host A, robots 2-3 a relay
    router on host B that dials the world over the `wan` network. The run completes (every
    robot arrives, no contact); robots behind router-b are one router further from the world
    (`wall_latency_ms_by_router`); a robot's certificate on host B gets nothing through
    router-b but its own keys."""
    demo = demo_factory("routers", time_scale=TIME_SCALE_ROUTERS,
                        files=("compose.routers.yaml",))
    t0 = time.monotonic()
    demo.compose("up", "--no-build", "--detach", timeout_s=UP_S)
    demo.wait_event("start", UP_S + 300.0)
    rogue = _run(["docker", "run", "--rm", "--network", f"{demo.project}_host-b",
                  "-v", f"{demo.project}_tls-robot-2:/tls:ro", "--entrypoint", "python",
                  docker_setup.image, "-c", RELAY_ROGUE, demo.run_id], 120.0, check=False)
    rogue_out = rogue.stdout + rogue.stderr
    assert rogue.returncode == 0, rogue_out[-3000:]
    assert "world: unreachable" in rogue_out, rogue_out[-3000:]
    assert "sent, own key matched: True" in rogue_out, rogue_out[-3000:]
    status = demo.wait_exit("orchestrator", RUN_S)
    assert status == ExitCode.OK, demo.logs("orchestrator")[-4000:]
    assert demo.wait_exit("router-b", 60.0) == 0, demo.logs("router-b")[-3000:]
    docker_setup.timings["routers_case_s"] = time.monotonic() - t0

    containers = demo.containers()
    assert sorted(containers) == sorted(["certs", *HOST_OF])
    for service, c in containers.items():
        assert not c["State"]["Running"] and c["State"]["ExitCode"] == 0, (service, c["State"])
        if service == "certs":
            continue
        nets = {n[len(demo.project) + 1:] for n in c["NetworkSettings"]["Networks"]}
        wan = {"wan"} if service in ("world", "router-b") else set()
        assert nets == {HOST_OF[service], *wan}, (service, nets)
        tls = [m["Name"] for m in c["Mounts"] if m["Destination"] == "/tls"]
        assert len(tls) == 1 and tls[0].endswith(f"_tls-{service}"), (service, tls)
    for rid in range(ROBOTS_D):
        log = demo.logs(f"robot-{rid}")
        router = "router-b" if rid >= 2 else "world"
        assert [s["connect"] for s in robot_starts(log)] == [f"tls/{router}:7447"], log[-2000:]
        exit_line = next(line for line in log.splitlines() if f"robot {rid} exit:" in line)
        assert "reason='end (all_arrived)' code=0" in exit_line
        for counter in ("rejected=0", "refused_poses=0", "refused_control=0",
                        "refused_config=0"):
            assert f" {counter} " in exit_line + " ", exit_line
    assert "the run is over" in demo.logs("router-b")

    run_dir = demo.copy_run(tmp_path)
    assert_run_files(run_dir)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["success"] is True and metrics["contacts"] == 0
    assert metrics["robots"] == ROBOTS_D and metrics["arrived"] == ROBOTS_D
    events = [json.loads(line) for line in (run_dir / "events.jsonl").read_text().splitlines()]
    ready = next(e for e in events if e["kind"] == "world_ready")
    assert ready["relays"] == {"router-b": [2, 3]} and ready["zid"] == "e1f5"
    end = next(e for e in events if e["kind"] == "end")
    # Only the rogue's puts on robot 2's own key reached the world (and were rejected there).
    assert set(end["rejected_by_key"]) == {f"eifp/{demo.run_id}/cmd/2"}, end
    by = metrics["wall_latency_ms_by_router"]
    assert sorted(by) == ["router-b", "world"]
    for group in by.values():
        assert group["transport"]["n"] > 100 and group["sense_to_act"]["n"] > 100
    # One router more, both ways: pose out and command back take longer behind router-b.
    assert by["router-b"]["transport"]["p50"] > by["world"]["transport"]["p50"], by
    figures = {g: {st: (by[g][st]["p50"], by[g][st]["p99"])
                   for st in ("transport", "sense_to_act", "pose_to_robot", "cmd_to_world")}
               for g in by}
    print(f"\nwall latency p50/p99 [ms] by router: {figures}")
    print(f"docker demo timings: {docker_setup.timings}")


def test_setup_g_override_runs_16_robot_containers(compose_command: list[str]) -> None:
    """compose.setup-g.yaml turns the demo into setup G: 16 robot services, ids 0..15 (the
    configuration only, no engine needed; the 16-container run is too heavy for every CI
    run)."""
    setup = DockerSetup(compose_command, {**os.environ, "EIFP_IMAGE": USER_IMAGE}, USER_IMAGE)
    demo = Demo(setup, "g", files=("compose.yaml", "compose.setup-g.yaml"))
    config = yaml.safe_load(demo.compose("config", timeout_s=EXEC_S).stdout)
    services = config["services"]
    robots = {name: s for name, s in services.items() if name.startswith("robot-")}
    assert sorted(robots) == sorted(robot_services(16))
    ids = sorted(int(s["environment"]["ROBOT_ID"]) for s in robots.values())
    assert ids == list(range(16))
    for name in ("world", "orchestrator"):
        env = services[name]["environment"]
        assert env["SETUP"] == "setup_g" and str(env["ROBOTS"]) == "16"
        assert env["RUN_ID"] == demo.run_id
    assert all(s["environment"]["RUN_ID"] == demo.run_id for s in robots.values())
    # Each robot mounts its own certificate volume only; the certs service writes them all.
    def mounts(service: dict) -> list[tuple[str, str]]:
        """(source, target) of each volume, short ("src:dst:rw") or long syntax."""
        out = []
        for v in service.get("volumes", []):
            if isinstance(v, str):
                src, dst = v.split(":")[:2]
            else:
                src, dst = v["source"], v["target"]
            out.append((src, dst))
        return out

    for name, s in robots.items():
        tls = [src for src, dst in mounts(s) if dst == "/tls"]
        assert tls == [f"tls-{name}"], (name, s.get("volumes"))
    assert str(services["certs"]["environment"]["ROBOTS"]) == "16"
    certs = {src for src, _ in mounts(services["certs"])}
    assert {f"tls-{name}" for name in robots} | {"tls-world", "tls-orchestrator"} <= certs


def test_docker_run_image_orchestrator_runs_the_cli(docker_setup: DockerSetup) -> None:
    """`docker run --rm IMAGE orchestrator list` (docs/docker.md) lists at once; it used to
    take the demo's role and wait 300 s for a certificate."""
    t0 = time.monotonic()
    proc = _run(["docker", "run", "--rm", docker_setup.image, "orchestrator", "list"], 120.0)
    assert "setup_d" in proc.stdout and "eifp-mpc" in proc.stdout, proc.stdout[-2000:]
    assert time.monotonic() - t0 < 60.0


def test_zz_the_docker_layer_leaves_the_host_as_found() -> None:
    """Last in the module: what the tests built is removed (`docker images -a` as before
    the build) and the working tree is as the module found it (no wheels, no run copies)."""
    for setup in SETUP:
        before = setup.images_before
        setup.cleanup()
        if before is not None:
            kept = {_image_id(image) for image in setup.kept}
            assert _image_ids() <= before | kept, "images left behind by the docker layer"
    after = _tree_state()
    changed = sorted(p for p in set(after) | set(TREE_BEFORE)
                     if after.get(p) != TREE_BEFORE.get(p))
    assert not changed, f"the docker layer changed the working tree: {changed[:20]}"
