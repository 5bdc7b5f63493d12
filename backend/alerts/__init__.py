"""Alerts (issue 13, item 7): a silent logger, a fault found by the diagnosis, a tracker
performance ratio below a threshold — each raised once when its condition starts and
cleared once when it ends, stored in ``alerts``, shown on the dashboard, read at
``GET /api/v1/alerts`` and POSTed as JSON to ``HELIOTWIN_ALERT_WEBHOOK_URL``.

- :mod:`backend.alerts.rules` — the conditions, as pure functions of what the service
  knows (last readings, the diagnosis answer), with their words;
- :mod:`backend.alerts.webhook` — the webhook sender: its own thread, a bounded queue,
  retries with exponential backoff; never waited for by anything else;
- :mod:`backend.alerts.service` — the evaluator thread (``heliotwin-alerts``): every
  ``HELIOTWIN_ALERT_INTERVAL_S`` it evaluates the rules, raises and clears alerts
  through the writer and hands their events to the sender; the read side of the API, and
  an operator's acknowledgement of an active alert (who, when, a note).
"""
