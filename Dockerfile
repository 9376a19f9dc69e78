# Bearings service image: HTTP/WebSocket API on 8000, viser view on 8080.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    NUMBA_CACHE_DIR=/tmp/numba-cache

# espeak-ng gives POST /speech an offline voice.
RUN apt-get update \
    && apt-get install -y --no-install-recommends espeak-ng \
    && rm -rf /var/lib/apt/lists/*

RUN useradd --create-home --uid 10001 bearings
WORKDIR /srv/bearings

# A regular (non-editable) install of the wheel: the bundled maps and the demo page
# (maps/ and static/ at the top level) travel inside the package, so the source folder
# is not needed at run time and is removed. The numba cache goes to NUMBA_CACHE_DIR.
COPY pyproject.toml README.md LICENSE ./
COPY app ./app
COPY maps ./maps
COPY static ./static
RUN pip install . && rm -rf /srv/bearings/* && mkdir -p /tmp/numba-cache \
    && chown bearings:bearings /tmp/numba-cache

USER bearings
# Compile the numba kernels into the image's cache (about 17 s), so a container on the
# same kind of CPU starts in about a second; another CPU recompiles once at start-up,
# before the server answers anything (hence the 60 s start period below), never on a
# request.
RUN python -c "from app.localization.filter import warm_up; warm_up()"
EXPOSE 8000 8080

HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD python -c "import urllib.request,sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4).status == 200 else 1)"

# Reachable from outside the container, so API keys are required: mount a key file at
# /run/secrets/bearings-keys (docs/SECURITY.md). The live view stays on the container's
# loopback unless BEARINGS_VISER_HOST says otherwise.
ENV BEARINGS_API_KEYS_FILE=/run/secrets/bearings-keys
CMD ["bearings", "serve", "--host", "0.0.0.0", "--port", "8000", "--viser-port", "8080"]
