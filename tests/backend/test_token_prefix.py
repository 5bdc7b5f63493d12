"""A token named by the prefix ``heliotwin token list`` shows (``backend.auth.find_token``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from backend.auth import UnknownToken, create_token, revoke_token
from backend.settings import get_settings
from backend.sites import Registry, sync_sites
from backend.storage.engine import make_engine, run_migrations


def test_revoking_by_the_listed_prefix_names_the_id_to_use(tmp_path: Path) -> None:
    engine = make_engine(get_settings(database_url=f"sqlite:///{tmp_path / 'tokens.sqlite'}"))
    try:
        run_migrations(engine)
        with engine.begin() as conn:
            sync_sites(conn, [i.site for i in Registry.load_files(tmp_path).sites.values()])
            token = create_token(conn, "tehuantepec", label="roof logger")
            with pytest.raises(UnknownToken) as err:
                revoke_token(conn, token[:10])
            msg = str(err.value)
            assert f"{token[:10]} is the token_prefix" in msg
            assert "`heliotwin token revoke 1`" in msg
            # an unknown token is still "no write token", and the real one still revokes
            with pytest.raises(UnknownToken, match="no write token with token ht_nothere"):
                revoke_token(conn, "ht_nothere_at_all")
            info, _ = revoke_token(conn, token)
            assert info.id == 1 and info.revoked_at is not None
    finally:
        engine.dispose()
