"""Delivery credentials: sent in headers, never shown (errors, logs, status, config echo)."""

from __future__ import annotations

import base64
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from monitor.alerts.alertmanager import HttpAuth, post_json, redact_url
from monitor.alerts.config import AlertsConfig
from monitor.alerts.outbox import PermanentDeliveryError


@pytest.fixture()
def server():
    seen: list[str | None] = []

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):  # noqa: N802
            self.rfile.read(int(self.headers["Content-Length"]))
            seen.append(self.headers.get("Authorization"))
            self.send_response(401 if self.path == "/deny" else 200)
            self.end_headers()

        def log_message(self, *args):
            pass

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield httpd.server_address[1], seen
    httpd.shutdown()
    httpd.server_close()


def test_basic_auth_from_the_url_and_bearer_from_env_and_file(server, tmp_path, monkeypatch):
    port, seen = server
    post_json(f"http://am:s3cret@127.0.0.1:{port}/api/v2/alerts", b"[]", 5, HttpAuth())
    assert seen[-1] == "Basic " + base64.b64encode(b"am:s3cret").decode()
    monkeypatch.setenv("AM_TOKEN", "tok-env")
    post_json(f"http://127.0.0.1:{port}/", b"[]", 5, HttpAuth(bearer_token_env="AM_TOKEN"))
    assert seen[-1] == "Bearer tok-env"
    (tmp_path / "pw").write_text("pw-file\n")
    post_json(f"http://127.0.0.1:{port}/", b"[]", 5,
              HttpAuth(username="u", password_file=str(tmp_path / "pw")))
    assert seen[-1] == "Basic " + base64.b64encode(b"u:pw-file").decode()


def test_errors_and_config_never_show_the_password(server):
    port, _ = server
    url = f"http://am:s3cret@127.0.0.1:{port}/deny"
    with pytest.raises(PermanentDeliveryError) as exc:
        post_json(url, b"[]", 5, HttpAuth())
    assert "s3cret" not in str(exc.value) and "***@127.0.0.1" in str(exc.value)
    assert redact_url(url) == f"http://***@127.0.0.1:{port}/deny"
    with pytest.raises(ValueError) as bad:
        AlertsConfig.from_dict({"alertmanager": {"url": "ftp://am:s3cret@host"}})
    assert "s3cret" not in str(bad.value)
    with pytest.raises(OSError, match="environment variable AM_MISSING"):
        HttpAuth(bearer_token_env="AM_MISSING").header("http://x")
