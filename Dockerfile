# One image for every petswarm process (hub, robots, user, watch); compose.yaml picks the command.
FROM python:3.11-slim
ENV PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1 PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
# Nothing runs as root: the processes only read /app and talk TCP (USER is set after the installs).
RUN useradd --create-home --uid 10001 petswarm
WORKDIR /app
# Dependencies first, in a layer of their own: only a change of pyproject.toml installs them again, so a
# change of the sources rebuilds in seconds. The list is pyproject.toml's, read with the standard library.
COPY pyproject.toml ./
RUN python -c "import tomllib; p = tomllib.load(open('pyproject.toml', 'rb')); \
print('\n'.join(p['build-system']['requires'] + p['project']['dependencies']))" > /tmp/requirements.txt \
 && pip install -r /tmp/requirements.txt && rm /tmp/requirements.txt
# The sources: installed without dependencies or build isolation (nothing is fetched here).
COPY README.md ./
COPY radio_hub radio_hub
COPY petswarm petswarm
COPY cli cli
COPY examples examples
RUN pip install --no-deps --no-build-isolation . && rm -rf build *.egg-info
USER petswarm
ENTRYPOINT ["petswarm"]
