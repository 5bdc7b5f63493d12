"""MQTT ingestion beside HTTP, and Home Assistant discovery (``docs/service.md``)."""
