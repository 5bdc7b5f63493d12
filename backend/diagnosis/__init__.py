"""Diagnosis: the tracker measured against the twin under the sky the fixed array saw (issue 13)."""
