"""Response models of the HTTP API: one module per resource, ``XRead`` names.

They are what ``/openapi.json`` declares for every 2xx body (each route sets
``response_model``), separate from the ORM tables (``backend/storage/tables.py``) and
from the request models. A physical quantity carries its unit in its field name
(DESIGN.md, Conventions). Routes that build a large answer themselves (orjson) return
that ``Response`` unchanged — FastAPI skips validation for a ``Response`` — so the model
documents the shape without costing a validation pass; ``tests/backend/
test_openapi_contracts.py`` checks real answers against their models.
"""
