"""MQTT transport: one paho-mqtt client (one connection, one last will) per vehicle, all
served from the simulation's own thread.

There is no network thread per client: ``poll(timeout_s)`` waits on every socket at once
(``selectors``) and lets paho read, write and keep alive; ``flush()`` publishes what the
vehicles queued. A thousand vehicles are a thousand sockets and no thread. Each vehicle's
client sets its last will (``connection`` = CONNECTIONBROKEN, QoS 1, retained) before
connecting, then publishes ONLINE, its factsheet (retained) and a state. One more client, the
fleet's receiver, subscribes to ``.../+/order`` and ``.../+/instantActions`` and hands each
message to its vehicle: two subscriptions in the broker instead of two per vehicle (a broker
that matches every message against every subscription, as amqtt does, would otherwise slow
down with the square of the fleet). A lost connection is retried every ``retry_s``; on
reconnecting a vehicle republishes all of it.
"""

from __future__ import annotations

import json
import resource
import selectors
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass
from urllib.parse import urlparse

import paho.mqtt.client as mqtt

from agvsim.fleet.vehicle import Vehicle

QOS = {"connection": 1}  # every other topic: QoS 0 (VDA 5050 6.2)


@dataclass(frozen=True)
class BrokerAddress:
    host: str
    port: int

    @classmethod
    def parse(cls, url: str) -> BrokerAddress:
        """``mqtt://HOST:PORT`` (port 1883 when left out)."""
        u = urlparse(url if "://" in url else f"mqtt://{url}")
        if u.scheme not in ("mqtt", "tcp") or not u.hostname:
            raise ValueError(f"broker {url!r}: expected mqtt://HOST:PORT")
        try:
            port = u.port or 1883
        except ValueError:
            raise ValueError(f"broker {url!r}: the port must be a number 1..65535") from None
        return cls(u.hostname, port)


def raise_file_limit(n: int) -> None:
    """Let this process hold ``n`` sockets and more, as far as the hard limit allows."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = min(hard, max(soft, n + 256)) if hard != resource.RLIM_INFINITY else max(soft, n + 256)
    if want > soft:
        resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))


def _read_all(c: mqtt.Client, most: int = 1000) -> None:
    """Read every packet waiting on the socket (paho's loop_read takes one QoS 0 message a
    call; the fleet receiver gets the orders of every vehicle on one socket)."""
    for _ in range(most):
        c.loop_read()
        sock = c.socket()
        if not isinstance(sock, socket.socket):
            return
        try:
            if not sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT):
                return  # closed: paho notices at its next read
        except OSError:  # BlockingIOError: nothing more to read
            return


class _Link:
    """One connection: a vehicle's (publishes, holds the last will) or the fleet receiver's
    (``vehicle`` None; subscribes to ``topics``)."""

    def __init__(
        self,
        transport: MqttTransport,
        vehicle: Vehicle | None,
        prefix: str,
        topics: Sequence[str] = (),
    ):
        self.t, self.vehicle, self.prefix, self.topics = transport, vehicle, prefix, list(topics)
        self.online = False
        self.next_try_s = 0.0
        c = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2, client_id=prefix.replace("/", "_"), clean_session=True
        )
        if vehicle is not None:
            will = vehicle.connection(vehicle.dialect.broken)
            c.will_set(f"{prefix}/connection", json.dumps(will), qos=1, retain=True)
        c.on_connect = self._on_connect
        c.on_disconnect = self._on_disconnect
        c.on_message = self._on_message
        c.on_socket_open = lambda _c, _u, sock: transport._watch(sock, self)
        c.on_socket_close = lambda _c, _u, sock: transport._unwatch(sock)
        c.on_socket_register_write = lambda _c, _u, sock: transport._want_write(sock, self, True)
        c.on_socket_unregister_write = lambda _c, _u, sock: transport._want_write(sock, self, False)
        self.client = c

    def connect(self) -> None:
        self.next_try_s = time.monotonic() + self.t.retry_s
        try:
            self.client.connect(self.t.address.host, self.t.address.port, keepalive=15)
        except OSError:
            self.online = False

    def _on_connect(self, client, _u, _flags, reason, _props) -> None:
        if reason.is_failure:
            return
        self.online = True
        if self.topics:
            client.subscribe([(t, 0) for t in self.topics])
        if self.vehicle is not None:
            self.vehicle.publish_all()
            self.t._flush_one(self)

    def _on_disconnect(self, _c, _u, _flags, _reason, _props) -> None:
        self.online = False
        self.next_try_s = time.monotonic() + self.t.retry_s

    def _on_message(self, _c, _u, msg) -> None:
        self.t._route(msg.topic, msg.payload)

    def publish(self, topic: str, message: dict, retain: bool) -> mqtt.MQTTMessageInfo:
        return self.client.publish(
            f"{self.prefix}/{topic}",
            json.dumps(message, separators=(",", ":")),
            qos=QOS.get(topic, 0),
            retain=retain,
        )


class MqttTransport:
    def __init__(
        self,
        address: BrokerAddress,
        vehicles: Sequence[Vehicle],
        interface_name: str,
        retry_s: float = 1.0,
    ):
        self.address, self.retry_s = address, retry_s
        raise_file_limit(len(vehicles))
        self.sel = selectors.DefaultSelector()
        prefixes = {
            v.cfg.serial: f"{interface_name}/{v.cfg.dialect.major}/{v.cfg.manufacturer}/"
            f"{v.cfg.serial}"
            for v in vehicles
        }
        self.links = [_Link(self, v, prefixes[v.cfg.serial]) for v in vehicles]
        self._by_prefix = {link.prefix: link.vehicle for link in self.links}
        groups = sorted({p.rsplit("/", 1)[0] for p in prefixes.values()})
        topics = [f"{g}/+/{t}" for g in groups for t in ("order", "instantActions")]
        receiver = f"{interface_name}/agvsim-fleet-{id(self):x}"
        self._echo_topic = f"{receiver}/closing"  # see close()
        self._echoed = False
        self.receiver = _Link(self, None, receiver, [*topics, self._echo_topic])
        self._all = [self.receiver, *self.links]
        self._last_misc = 0.0
        self._pending: set[_Link] = set()  # links with output queued since the last write
        self._writable: set[_Link] = set()  # links registered for EVENT_WRITE

    # socket bookkeeping (paho calls these)
    def _watch(self, sock, link: _Link) -> None:
        self.sel.register(sock, selectors.EVENT_READ, link)

    def _unwatch(self, sock) -> None:
        try:
            self.sel.unregister(sock)
        except (KeyError, ValueError):
            pass

    def _want_write(self, sock, link: _Link, on: bool) -> None:
        # output is written right after each flush (``_write_pending``); only a socket that
        # could not take all of it waits for EVENT_WRITE, so a publish costs no selector call
        if on:
            self._pending.add(link)
        elif link in self._writable:
            self._writable.discard(link)
            try:
                self.sel.modify(sock, selectors.EVENT_READ, link)
            except (KeyError, ValueError):
                pass

    def _write_pending(self) -> None:
        pending, self._pending = self._pending, set()
        for link in pending:
            c = link.client
            sock = c.socket()
            if sock is None:
                continue
            c.loop_write()
            if c.want_write() and link not in self._writable:
                self._writable.add(link)
                try:
                    self.sel.modify(sock, selectors.EVENT_READ | selectors.EVENT_WRITE, link)
                except (KeyError, ValueError):
                    pass

    def _route(self, topic: str, payload: bytes) -> None:
        if topic == self._echo_topic:
            self._echoed = True
            return
        prefix, name = topic.rsplit("/", 1)
        vehicle = self._by_prefix.get(prefix)
        if vehicle is not None:
            vehicle.receive(name, payload)

    def connect(self, timeout_s: float = 10.0) -> int:
        """Connect every vehicle; returns how many are online after ``timeout_s`` at most."""
        for link in self._all:
            link.connect()
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout_s and not all(x.online for x in self._all):
            if not any(x.client.socket() is not None for x in self._all):
                break  # every connection was refused
            self.poll(0.05)
        return sum(x.online for x in self.links) if self.receiver.online else 0

    def poll(self, timeout_s: float = 0.0) -> None:
        """Serve the sockets for up to ``timeout_s`` (read, write, keepalive, reconnect)."""
        self._write_pending()
        for key, events in self.sel.select(timeout=max(0.0, timeout_s)):
            c = key.data.client
            if events & selectors.EVENT_READ:
                _read_all(c)
            if events & selectors.EVENT_WRITE:
                c.loop_write()
        now = time.monotonic()
        if now - self._last_misc >= 1.0:
            self._last_misc = now
            for link in self._all:
                link.client.loop_misc()
                if not link.online and now >= link.next_try_s and link.client.socket() is None:
                    link.connect()

    def _flush_one(self, link: _Link) -> None:
        assert link.vehicle is not None
        for topic, msg, retain in link.vehicle.drain():
            link.publish(topic, msg, retain)

    def flush(self) -> None:
        """Publish everything the vehicles queued (dropped while a vehicle is offline: its
        state is republished whole when it reconnects)."""
        for link in self.links:
            v = link.vehicle
            if v is None or not v.outbox:  # most vehicles publish nothing in a step
                continue
            if link.online:
                self._flush_one(link)
            else:
                v.drain()
        self._write_pending()

    def close(self, timeout_s: float = 5.0) -> None:
        """Publish OFFLINE and disconnect cleanly (no last will). Returns once the broker has
        passed the OFFLINE messages on (or after ``timeout_s``), so a broker stopped right
        after (the embedded one) does not swallow them: each is acknowledged (QoS 1), then a
        message the receiver sends itself comes back through the broker after them."""
        t_end = time.monotonic() + timeout_s
        sent = [
            link.publish("connection", link.vehicle.connection("OFFLINE"), True)
            for link in self.links
            if link.online and link.vehicle is not None
        ]
        while time.monotonic() < t_end and not all(m.is_published() for m in sent):
            self.poll(0.02)
        if self.receiver.online:
            self._echoed = False
            self.receiver.client.publish(self._echo_topic, b"", qos=0)
            while time.monotonic() < t_end and not self._echoed and self.receiver.online:
                self.poll(0.02)
        for link in self._all:
            if link.online:
                link.client.disconnect()
        while time.monotonic() < t_end and any(
            x.client.want_write() for x in self._all if x.client.socket() is not None
        ):
            self.poll(0.05)
        for link in self._all:
            link.client.loop_misc()
        self.sel.close()
