"""A headless Chromium driven through the DevTools protocol, with a minimal WebSocket client from the standard library
(no third-party package): open a page, evaluate JavaScript in it, take screenshots. Used by check_web_map_replay.py.
"""
import base64
import json
import os
import signal
import socket
import struct
import subprocess
import tempfile
import time
import urllib.request


class DevToolsError(RuntimeError):
    pass


class WebSocket:
    """Text frames over one TCP connection (RFC 6455, client side: frames masked, no extensions)."""

    def __init__(self, url, timeout_s=60.0):
        assert url.startswith('ws://'), url
        host_port, _, path = url[5:].partition('/')
        host, _, port = host_port.partition(':')
        self.sock = socket.create_connection((host, int(port)), timeout=timeout_s)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(('GET /%s HTTP/1.1\r\nHost: %s\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n'
                           'Sec-WebSocket-Key: %s\r\nSec-WebSocket-Version: 13\r\n\r\n' % (path, host_port, key))
                          .encode())
        reply = b''
        while b'\r\n\r\n' not in reply:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise DevToolsError('the DevTools server closed the connection during the handshake')
            reply += chunk
        head, _, self.pending = reply.partition(b'\r\n\r\n')
        if not head.startswith(b'HTTP/1.1 101'):
            raise DevToolsError('WebSocket handshake refused: %s' % head.decode(errors='replace'))

    def send(self, text):
        payload = text.encode()
        header = bytes([0x81])  # FIN, text
        n = len(payload)
        if n < 126:
            header += bytes([0x80 | n])
        elif n < 65536:
            header += bytes([0x80 | 126]) + struct.pack('!H', n)
        else:
            header += bytes([0x80 | 127]) + struct.pack('!Q', n)
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(header + mask + masked)

    def _read(self, n):
        while len(self.pending) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise DevToolsError('the DevTools connection closed')
            self.pending += chunk
        data, self.pending = self.pending[:n], self.pending[n:]
        return data

    def receive(self):
        message = b''
        while True:
            b0, b1 = self._read(2)
            opcode, n = b0 & 0x0f, b1 & 0x7f
            if n == 126:
                n = struct.unpack('!H', self._read(2))[0]
            elif n == 127:
                n = struct.unpack('!Q', self._read(8))[0]
            mask = self._read(4) if b1 & 0x80 else None
            payload = self._read(n)
            if mask:
                payload = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
            if opcode == 8:
                raise DevToolsError('the DevTools connection was closed by the browser')
            if opcode == 9:  # ping: answer, then go on reading
                continue
            message += payload
            if b0 & 0x80:
                return message.decode()

    def close(self):
        try:
            self.sock.close()
        except OSError:
            pass


class HeadlessChromium:
    """Debian's chromium, headless, one page open at `url`; stop() ends it (the process group it was started in)."""

    def __init__(self, url, width=1280, height=800, log_path=None):
        self.profile = tempfile.mkdtemp(prefix='exocet_chromium_')
        log = open(log_path, 'w') if log_path else subprocess.DEVNULL
        self.process = subprocess.Popen(
            ['chromium', '--headless', '--no-sandbox', '--disable-gpu', '--no-first-run', '--disable-extensions',
             '--hide-scrollbars', '--remote-debugging-port=0', '--user-data-dir=' + self.profile,
             '--window-size=%d,%d' % (width, height), url],
            stdout=log, stderr=log, start_new_session=True)
        port_file = os.path.join(self.profile, 'DevToolsActivePort')
        end = time.time() + 60
        while not (os.path.exists(port_file) and open(port_file).read().count('\n') >= 1):
            if time.time() > end or self.process.poll() is not None:
                self.stop()
                raise DevToolsError('chromium did not start its DevTools server')
            time.sleep(0.1)
        port = int(open(port_file).read().split('\n')[0])
        page = None
        while page is None:
            targets = json.loads(urllib.request.urlopen('http://127.0.0.1:%d/json/list' % port, timeout=30).read())
            page = next((t for t in targets if t.get('type') == 'page'), None)
            if page is None:
                if time.time() > end:
                    self.stop()
                    raise DevToolsError('chromium opened no page')
                time.sleep(0.1)
        self.socket = WebSocket(page['webSocketDebuggerUrl'])
        self.next_id = 0

    def call(self, method, **params):
        self.next_id += 1
        self.socket.send(json.dumps({'id': self.next_id, 'method': method, 'params': params}))
        while True:
            message = json.loads(self.socket.receive())
            if message.get('id') == self.next_id:
                if 'error' in message:
                    raise DevToolsError('%s: %s' % (method, message['error']))
                return message.get('result', {})

    def evaluate(self, expression):
        """The value of a JavaScript expression in the page (JSON-serialisable)."""
        result = self.call('Runtime.evaluate', expression=expression, returnByValue=True)
        if 'exceptionDetails' in result:
            raise DevToolsError('%s: %s' % (expression, result['exceptionDetails']))
        return result['result'].get('value')

    def screenshot(self, path):
        data = self.call('Page.captureScreenshot', format='png')['data']
        with open(path, 'wb') as f:
            f.write(base64.b64decode(data))
        return path

    def stop(self):
        if getattr(self, 'socket', None):
            self.socket.close()
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        subprocess.run(['rm', '-rf', self.profile])


def screenshot_file(url, path, width=1280, height=800, budget_ms=8000):
    """A screenshot of `url` (file:// too) by a one-shot headless chromium, after `budget_ms` of virtual time; the
    page's title (from the dumped DOM) is returned."""
    profile = tempfile.mkdtemp(prefix='exocet_chromium_')
    common = ['chromium', '--headless', '--no-sandbox', '--disable-gpu', '--no-first-run', '--hide-scrollbars',
              '--user-data-dir=' + profile, '--window-size=%d,%d' % (width, height),
              '--virtual-time-budget=%d' % budget_ms]
    subprocess.run(common + ['--screenshot=' + path, url], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   timeout=120, start_new_session=True)
    dom = subprocess.run(common + ['--dump-dom', url], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                         timeout=120, start_new_session=True).stdout.decode(errors='replace')
    subprocess.run(['rm', '-rf', profile])
    start = dom.find('<title>')
    return dom[start + 7:dom.find('</title>')] if start >= 0 else ''
