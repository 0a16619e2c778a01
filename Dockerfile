# One image for every petswarm process (hub, robots, user); compose.yaml picks the command.
FROM python:3.11-slim
WORKDIR /app
COPY pyproject.toml README.md ./
COPY radio_hub radio_hub
COPY petswarm petswarm
COPY cli cli
COPY examples examples
RUN pip install --no-cache-dir .
ENV PYTHONUNBUFFERED=1
ENTRYPOINT ["petswarm"]
