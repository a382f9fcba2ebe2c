"""Headless Chromium over the DevTools protocol: the viewer's page loaded, read and photographed.

Used by the viewer's `--screenshot` and its browser test. The driver is the DevTools protocol
over a websocket, with the `websockets` client that viser already depends on: nothing to
install but the browser. Chromium's own `--screenshot` / `--dump-dom` cannot wait for the
scene, which reaches the page over viser's websocket after the load event; selenium needs a
chromedriver of the browser's exact version, playwright a Node.js runtime.

The browser runs with a fresh, empty profile and without any network activity of its own
(`FLAGS`: no sync, updates, QUIC or first-run fetches, which hang on a closed network), and
renders WebGL in software (SwiftShader), so no GPU or display is needed.
"""

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--remote-debugging-port=0")
EXECUTABLES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

# viser warns in a notification that WebGL runs in software; a screenshot is taken without it.
_CLOSE_NOTIFICATIONS = ("document.querySelectorAll('.mantine-Notification-closeButton')"
                        ".forEach(b => b.click())")


class BrowserError(RuntimeError):
  """The browser could not be started or did not answer."""


def find_chromium():
  """The path of a Chromium (or Chrome) executable on PATH, or None."""
  for name in EXECUTABLES:
    path = shutil.which(name)
    if path:
      return path
  return None


class Browser:
  """One headless Chromium with one page, driven over the DevTools protocol.

    with Browser() as browser:
      browser.open(url)
      browser.wait_for_text("next #1")
      browser.screenshot("page.png")
  """

  def __init__(self, executable=None, size=(1280, 800), timeout=30.0):
    self.executable = executable or find_chromium()
    if self.executable is None:
      raise BrowserError(f"no Chromium on PATH (looked for {', '.join(EXECUTABLES)}); on "
                         "Debian: apt-get install chromium")
    self.size = size
    self.timeout = timeout
    self.profile = None
    self.process = None
    self.socket = None
    self._id = 0

  def __enter__(self):
    self.start()
    return self

  def __exit__(self, *exc):
    self.close()

  def start(self):
    from websockets.sync.client import connect

    self.profile = tempfile.mkdtemp(prefix="mfsample-chromium-")
    self.process = subprocess.Popen(
        [self.executable, *FLAGS, f"--user-data-dir={self.profile}",
         f"--window-size={self.size[0]},{self.size[1]}", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # Chromium writes the port it chose to this file of the profile once it listens.
    port_file = os.path.join(self.profile, "DevToolsActivePort")
    deadline = time.monotonic() + self.timeout
    port = None
    while port is None:
      if self.process.poll() is not None:
        raise BrowserError(f"{self.executable} exited with code {self.process.returncode}")
      if time.monotonic() > deadline:
        self.close()
        raise BrowserError(f"{self.executable} did not open its DevTools port within "
                           f"{self.timeout:.0f} s")
      try:
        with open(port_file) as f:
          port = int(f.readline())
      except (OSError, ValueError):
        time.sleep(0.1)
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
      pages = [t for t in json.load(r) if t.get("type") == "page"]
    self.socket = connect(pages[0]["webSocketDebuggerUrl"], max_size=None,
                          open_timeout=self.timeout)
    # The page exactly `size` (the window's size includes no browser chrome in headless mode,
    # but Chromium versions differ in what they subtract).
    self.call("Emulation.setDeviceMetricsOverride", width=int(self.size[0]),
              height=int(self.size[1]), deviceScaleFactor=1, mobile=False)

  def close(self):
    if self.socket is not None:
      self.socket.close()
      self.socket = None
    if self.process is not None:
      self.process.terminate()
      try:
        self.process.wait(10)
      except subprocess.TimeoutExpired:
        self.process.kill()
        self.process.wait()
      self.process = None
    if self.profile is not None:
      shutil.rmtree(self.profile, ignore_errors=True)
      self.profile = None

  def call(self, method, **params):
    """The result of one DevTools command (events in between are skipped)."""
    self._id += 1
    self.socket.send(json.dumps({"id": self._id, "method": method, "params": params}))
    while True:
      message = json.loads(self.socket.recv(timeout=self.timeout))
      if message.get("id") == self._id:
        if "error" in message:
          raise BrowserError(f"{method}: {message['error']}")
        return message.get("result", {})

  def evaluate(self, expression):
    """The value of a JavaScript expression in the page."""
    result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
    return result.get("result", {}).get("value")

  def open(self, url):
    self.call("Page.navigate", url=url)

  def text(self):
    """The page's visible text."""
    return self.evaluate("document.body ? document.body.innerText : ''") or ""

  def wait_for(self, expression, timeout=None):
    """Waits until a JavaScript expression is truthy; returns its value."""
    deadline = time.monotonic() + (timeout or self.timeout)
    while True:
      value = self.evaluate(expression)
      if value:
        return value
      if time.monotonic() > deadline:
        raise BrowserError(f"timed out waiting for {expression!r}")
      time.sleep(0.2)

  def wait_for_text(self, text, timeout=None):
    """Waits until the page shows `text`: in its visible text or as the value of a field
    (a dropdown shows its choice in an input)."""
    quoted = json.dumps(text)
    return self.wait_for(
        f"document.body && (document.body.innerText.includes({quoted}) || Array.from("
        f"document.querySelectorAll('input')).some(i => (i.value || '').includes({quoted})))",
        timeout)

  def screenshot(self, path, max_width=None, settle=2.0):
    """Saves the page as a PNG (notifications closed, after `settle` seconds for the scene to
    draw), shrunk to `max_width` pixels and to 256 colours when given (small files)."""
    self.evaluate(_CLOSE_NOTIFICATIONS)
    time.sleep(settle)
    data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
    with open(path, "wb") as f:
      f.write(data)
    if max_width:
      from PIL import Image

      with Image.open(path) as image:
        image = image.convert("RGB")
        if image.width > max_width:
          image = image.resize((max_width, round(image.height * max_width / image.width)),
                               Image.LANCZOS)
        image.quantize(256).save(path, optimize=True)
    return path
