# One image for every role of the docker-compose demo (compose.yaml): the world (a Zenoh
# router and the simulation), each robot, and the orchestrator. The role is the command:
# `world`, `robot` or `orchestrator` (see docker/entrypoint.sh).
#
# BASE_IMAGE: any image with CPython 3.11 and its venv module. The default needs a registry;
# without one, build a local base with docker/build-base-image.sh and pass
# --build-arg BASE_IMAGE=eifp-swarm-base:bookworm.
# Dependencies install from docker/wheels/ when it holds wheels (docker/fetch-wheels.sh, for
# builds where containers cannot reach PyPI), else from PyPI.
ARG BASE_IMAGE=python:3.11-slim

# --- the requirement list: runtime dependencies and build requirements, from pyproject.toml.
# Copied into the next stage by content, so editing other parts of pyproject.toml (tool
# settings, metadata) keeps the dependency layers cached.
FROM ${BASE_IMAGE} AS requirements
COPY pyproject.toml /tmp/pyproject.toml
RUN python3 -c 'import tomllib; m = tomllib.load(open("/tmp/pyproject.toml", "rb")); print("\n".join(m["build-system"]["requires"] + m["project"]["dependencies"]))' > /tmp/requirements.txt

# --- dependencies, in a stage of their own so the wheels never reach the final image -------
FROM ${BASE_IMAGE} AS deps
ENV PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_CACHE_DIR=1
RUN python3 -m venv /opt/venv
COPY --from=requirements /tmp/requirements.txt /tmp/requirements.txt
COPY docker/wheels/ /tmp/wheels/
# The project is built in the last stage without build isolation: its build requirements
# are installed here too.
RUN if ls /tmp/wheels/*.whl >/dev/null 2>&1; then \
        echo "installing from the wheels in docker/wheels"; \
        /opt/venv/bin/pip install --no-index --find-links /tmp/wheels -r /tmp/requirements.txt; \
    else \
        echo "docker/wheels is empty: installing from PyPI"; \
        /opt/venv/bin/pip install -r /tmp/requirements.txt; \
    fi

# --- the project ------------------------------------------------------------------------
# Everything that does not depend on the sources comes first: with this engine's storage
# driver every step after a source change costs seconds, so only the copy and the install
# follow the sources.
FROM ${BASE_IMAGE}
ENV PATH=/opt/venv/bin:$PATH \
    VIRTUAL_ENV=/opt/venv \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    MPLBACKEND=Agg
# The processes run as eifp (uid 1000), who also owns the venv (the project is installed
# into it as eifp, below). A named volume mounted at /runs starts as a copy of this
# directory, so it is owned by eifp too.
RUN useradd --uid 1000 --create-home --shell /bin/sh eifp \
    && mkdir -p /runs && chown eifp:eifp /runs
COPY --from=deps --chown=1000:1000 /opt/venv /opt/venv
COPY docker/entrypoint.sh /usr/local/bin/eifp-entrypoint
WORKDIR /home/eifp
ENTRYPOINT ["/usr/local/bin/eifp-entrypoint"]
CMD ["help"]
USER eifp
# The matplotlib font cache, built once here rather than at every orchestrator start.
RUN python -c 'import matplotlib.pyplot'
COPY --chown=1000:1000 pyproject.toml README.md /tmp/src/
COPY --chown=1000:1000 eifp_wire /tmp/src/eifp_wire
COPY --chown=1000:1000 agent /tmp/src/agent
COPY --chown=1000:1000 world /tmp/src/world
COPY --chown=1000:1000 orchestrator /tmp/src/orchestrator
RUN pip install --no-deps --no-build-isolation --no-index /tmp/src && rm -rf /tmp/src
