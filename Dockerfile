# heliotwin service image: API + dashboard on 8000, viser 3D twin on 8080.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    HELIOTWIN_HOST=0.0.0.0 \
    HELIOTWIN_DATABASE_URL=sqlite:////data/heliotwin.sqlite

WORKDIR /app
COPY pyproject.toml README.md ./
COPY backend ./backend
COPY sim ./sim
COPY vision ./vision
COPY frontend ./frontend
COPY data/sites ./data/sites
COPY data/plants ./data/plants
# editable: the service finds data/ and frontend/ beside its code in /app
RUN pip install --no-cache-dir -e . \
    && useradd --create-home --uid 1000 heliotwin \
    && mkdir -p /data && chown heliotwin /data

USER heliotwin
VOLUME ["/data"]
EXPOSE 8000 8080
HEALTHCHECK --interval=15s --timeout=3s --start-period=30s --retries=3 \
    CMD python -c "import urllib.request,sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=2).status == 200 else 1)"
CMD ["heliotwin", "serve", "--host", "0.0.0.0", "--port", "8000", "--viser-port", "8080"]
