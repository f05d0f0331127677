"""A throwaway redis-server for the tests of the redis store: loopback only, on a free port, in
a temporary directory, without persistence (no RDB, no AOF: the tests kill daemons, never redis,
unless they restart it on purpose, and then they want it empty).

`free_port()` is also what the failover test uses for HAProxy."""
import shutil
import socket
import subprocess
import time

REDIS_SERVER = shutil.which("redis-server")


def free_port():
    """A loopback TCP port nobody listened on a moment ago (bound to port 0, then closed)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ping(port, timeout=0.5):
    """True when a redis server answers PING on the port (RESP over a plain socket)."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
            s.sendall(b"*1\r\n$4\r\nPING\r\n")
            return s.recv(16).startswith(b"+PONG")
    except OSError:
        return False


class RedisServer:
    """redis-server on 127.0.0.1:`port`; start() and stop() may be called again (same port)."""

    def __init__(self, directory, port=None):
        self.dir = str(directory)
        self.port = port or free_port()
        self.proc = None

    def start(self, timeout=10):
        self.proc = subprocess.Popen(
            [REDIS_SERVER, "--port", str(self.port), "--bind", "127.0.0.1", "--save", "",
             "--appendonly", "no", "--dir", self.dir, "--logfile", "redis.log"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.time() + timeout
        while time.time() < deadline:
            if ping(self.port):
                return self
            if self.proc.poll() is not None:
                raise RuntimeError(f"redis-server exited ({self.proc.returncode}) on port {self.port}")
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"redis-server did not answer on port {self.port}")

    def stop(self):
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None

    @property
    def url(self):
        return f"redis://127.0.0.1:{self.port}"

    def command(self, *args, timeout=5):
        """One command in RESP (for tests that damage what the daemon stored): its raw reply."""
        import socket
        req = b"*%d\r\n" % len(args) + b"".join(
            b"$%d\r\n%s\r\n" % (len(a), a) for a in (x if isinstance(x, bytes) else str(x).encode()
                                                       for x in args))
        with socket.create_connection(("127.0.0.1", self.port), timeout=timeout) as c:
            c.sendall(req)
            return c.recv(65536)
