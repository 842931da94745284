"""A report printed by a real browser, headless: Chromium (``--print-to-pdf``) and Firefox (WebDriver's Print
command over its Marionette protocol, no driver needed), and the text of each printed page (poppler's
``pdftotext``). For tests/test_report_print.py and tests/bench/print_check.py; each function raises
:class:`Missing` naming what is not installed (Debian: ``apt-get install chromium firefox-esr poppler-utils``).
"""

from __future__ import annotations

import base64
import json
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

#: where Firefox's Marionette listens while it prints (its own throw-away profile says so)
MARIONETTE_PORT = 2929


class Missing(RuntimeError):
    """A program the printing needs is not installed."""


def _exe(*names: str) -> str:
    for n in names:
        p = shutil.which(n)
        if p:
            return p
    raise Missing(f"{names[0]} is not installed (Debian: apt-get install chromium firefox-esr poppler-utils)")


def chromium_pdf(html: Path, pdf: Path, *, browser_headers: bool = False) -> None:
    """``html`` printed to ``pdf`` (A4 from the page's ``@page``) by headless Chromium; ``browser_headers``:
    with Chromium's own print header and footer (title, date, URL, page x/y), as its print dialog's
    "Headers and footers" adds them."""
    exe = _exe("chromium", "chromium-browser", "google-chrome")
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                        f"--user-data-dir={profile}", f"--print-to-pdf={pdf}",
                        *([] if browser_headers else ["--no-pdf-header-footer"]), Path(html).resolve().as_uri()],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)


def firefox_pdf(html: Path, pdf: Path) -> str:
    """``html`` printed to ``pdf`` on A4 by headless Firefox (WebDriver ``Print``: no browser header or footer,
    the page's own margins); returns Firefox's version."""
    exe = _exe("firefox", "firefox-esr")
    version = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60).stdout.strip()
    with tempfile.TemporaryDirectory() as profile:
        Path(profile, "user.js").write_text(f'user_pref("marionette.port", {MARIONETTE_PORT});\n')
        proc = subprocess.Popen([exe, "--headless", "--marionette", "--no-remote", "-profile", profile],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            sock = _connect(MARIONETTE_PORT, 60.0)
            with sock, sock.makefile("rb") as f:
                _read(f)  # the server's hello
                calls = iter(range(1, 100))

                def command(name: str, params: dict) -> dict:
                    body = json.dumps([0, next(calls), name, params]).encode()
                    sock.sendall(str(len(body)).encode() + b":" + body)
                    _, _, error, result = _read(f)
                    if error:
                        raise RuntimeError(f"Firefox {name}: {error}")
                    return result

                command("WebDriver:NewSession", {"capabilities": {}})
                command("WebDriver:Navigate", {"url": Path(html).resolve().as_uri()})
                got = command("WebDriver:Print", {"page": {"width": 21.0, "height": 29.7}, "background": True,
                                                  "margin": {"top": 0, "bottom": 0, "left": 0, "right": 0}})
                Path(pdf).write_bytes(base64.b64decode(got["value"]))
        finally:
            proc.kill()
            proc.wait(timeout=30)
    return version


def _connect(port: int, timeout_s: float) -> socket.socket:
    end = time.monotonic() + timeout_s
    while True:
        try:
            return socket.create_connection(("127.0.0.1", port), timeout=60)
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.3)


def _read(f) -> list:
    """One Marionette message: ``length:json``."""
    n = b""
    while not n.endswith(b":"):
        c = f.read(1)
        if not c:
            raise ConnectionError("Firefox closed the Marionette connection")
        n += c
    return json.loads(f.read(int(n[:-1])))


def pages(pdf: Path) -> list[str]:
    """The text of each page of ``pdf`` (pdftotext, layout kept)."""
    exe = _exe("pdftotext")
    out = subprocess.run([exe, "-layout", str(pdf), "-"], check=True, capture_output=True, text=True, timeout=60)
    return out.stdout.split("\f")[:-1]
