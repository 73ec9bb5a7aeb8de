# texsynth job service: one image for the API and the workers (docker-compose.yml picks the command).
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    TEXSYNTH_DATA_DIR=/data \
    NUMBA_CACHE_DIR=/numba-cache

WORKDIR /app
COPY pyproject.toml README.md constraints.txt ./
COPY synth ./synth
COPY app ./app
COPY worker ./worker
COPY jobs ./jobs
RUN pip install -c constraints.txt '.[cluster]' \
    && useradd --create-home --uid 1000 texsynth \
    && mkdir -p /data /numba-cache && chown texsynth /data /numba-cache

USER texsynth
VOLUME ["/data", "/numba-cache"]
EXPOSE 8000
# API only; the workers are separate services (see docker-compose.yml)
CMD ["texsynth", "serve", "--host", "0.0.0.0", "--port", "8000", "--no-worker"]
