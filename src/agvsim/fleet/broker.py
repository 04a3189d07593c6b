"""The embedded MQTT broker: amqtt (pure Python, asyncio), bound to 127.0.0.1, anonymous, no
websockets. ``agvsim fleet`` starts it unless ``--broker`` names an external one (Debian's
Mosquitto is the reference).

It runs in a child process that agvsim starts and stops (``EmbeddedBroker``): there it uses
the second core instead of competing with the simulation for Python's GIL, which in one process
made every message wait for the simulation step. The child exits by itself when its parent
dies. ``in_thread=True`` runs it in a thread of this process instead.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing as mp
import os
import threading
from typing import Any

from agvsim.net import free_port


def _config(host: str, port: int) -> dict:
    return {
        "listeners": {"default": {"type": "tcp", "bind": f"{host}:{port}"}},
        "plugins": {"amqtt.plugins.authentication.AnonymousAuthPlugin": {"allow_anonymous": True}},
    }


def _quiet() -> None:
    for name in ("amqtt", "transitions"):  # shutdown notes are not the user's concern
        logging.getLogger(name).setLevel(logging.ERROR)


def _serve(host: str, port: int, parent: int, conn: Any) -> None:
    """The child process: serve until the parent says stop or disappears."""
    from amqtt.broker import Broker

    _quiet()

    async def main() -> None:
        broker = Broker(_config(host, port))
        try:
            await broker.start()
        except BaseException as err:  # noqa: BLE001 - reported to the parent
            conn.send(f"{type(err).__name__}: {err}")
            return
        conn.send("ready")
        loop = asyncio.get_running_loop()
        while os.getppid() == parent:
            if await loop.run_in_executor(None, conn.poll, 0.5):
                break  # the parent asks to stop
        await broker.shutdown()

    asyncio.run(main())


class EmbeddedBroker:
    def __init__(self, host: str = "127.0.0.1", port: int = 0, in_thread: bool = False):
        self.host, self.port = host, port or free_port(host)
        self.in_thread = in_thread
        self._proc: Any = None
        self._conn: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._broker: Any = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        return f"mqtt://{self.host}:{self.port}"

    def start(self, timeout_s: float = 20.0) -> EmbeddedBroker:
        if self.in_thread:
            return self._start_thread(timeout_s)
        ctx = mp.get_context("spawn")
        mine, theirs = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve,
            args=(self.host, self.port, os.getpid(), theirs),
            name="agvsim-mqtt-broker",
            daemon=True,
        )
        self._proc.start()
        self._conn = mine
        if not mine.poll(timeout_s):
            self.stop()
            raise RuntimeError(f"the embedded MQTT broker did not start in {timeout_s:g} s")
        answer = mine.recv()
        if answer != "ready":
            self.stop()
            raise OSError(
                f"the embedded MQTT broker could not listen on {self.host}:{self.port}: {answer}"
            )
        return self

    def _start_thread(self, timeout_s: float) -> EmbeddedBroker:
        from amqtt.broker import Broker

        _quiet()
        ready = threading.Event()
        failed: list[BaseException] = []
        loop = asyncio.new_event_loop()
        self._loop = loop

        def run() -> None:
            asyncio.set_event_loop(loop)
            try:
                self._broker = Broker(_config(self.host, self.port), loop=loop)
                loop.run_until_complete(self._broker.start())
            except BaseException as err:  # noqa: BLE001 - reported by start()
                failed.append(err)
                ready.set()
                return
            ready.set()
            loop.run_forever()

        self._thread = threading.Thread(target=run, name="agvsim-mqtt-broker", daemon=True)
        self._thread.start()
        if not ready.wait(timeout_s):
            raise RuntimeError(f"the embedded MQTT broker did not start in {timeout_s:g} s")
        if failed:
            raise OSError(
                f"the embedded MQTT broker could not listen on {self.host}:{self.port}: {failed[0]}"
            )
        return self

    def stop(self) -> None:
        if self._proc is not None:
            try:
                self._conn.send("stop")
            except (OSError, ValueError):
                pass
            self._proc.join(5.0)
            if self._proc.is_alive():
                self._proc.terminate()
                self._proc.join(5.0)
            self._proc = None
            return
        loop, broker = self._loop, self._broker
        if loop is None or broker is None or not loop.is_running():
            return
        fut = asyncio.run_coroutine_threadsafe(broker.shutdown(), loop)
        try:
            fut.result(timeout=5.0)
        except Exception:  # noqa: BLE001 - shutting down anyway
            pass
        loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def __enter__(self) -> EmbeddedBroker:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.stop()
