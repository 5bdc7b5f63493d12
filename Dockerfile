# heliotwin service image: API + dashboard on 8000, viser 3D twin on 8080.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    HELIOTWIN_HOST=0.0.0.0 \
    HELIOTWIN_DATABASE_URL=sqlite:////data/heliotwin.sqlite \
    HELIOTWIN_SITES_DIR=/data/user-sites

# A regular (not editable) install with the versions CI tested: the built-in sites and
# plants, the dashboard, the migrations and the vision model ship inside the package as
# package data (pyproject.toml, setup.py), so the sources are not needed once installed.
COPY pyproject.toml setup.py README.md constraints.txt /src/
COPY backend /src/backend
COPY sim /src/sim
COPY vision /src/vision
COPY frontend /src/frontend
RUN pip install --no-cache-dir -c /src/constraints.txt /src \
    && rm -rf /src \
    && useradd --create-home --uid 1000 heliotwin \
    && mkdir -p /data && chown heliotwin /data

USER heliotwin
WORKDIR /data
VOLUME ["/data"]
EXPOSE 8000 8080
HEALTHCHECK --interval=15s --timeout=3s --start-period=30s --retries=3 \
    CMD python -c "import urllib.request,sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=2).status == 200 else 1)"
CMD ["heliotwin", "serve", "--host", "0.0.0.0", "--port", "8000", "--viser-port", "8080"]
