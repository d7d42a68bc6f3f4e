"""A simulated service started without a token gets a random one, stored privately."""

import stat

from service.cli.serve import session_token


def test_session_token_is_random_private_and_stored(tmp_path):
    a = session_token(tmp_path)
    path = tmp_path / "token"
    assert path.read_text().strip() == a
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert len(a) >= 24
    assert session_token(tmp_path) != a  # a new one every start
