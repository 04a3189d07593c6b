"""The guidance topics of run.mcap (docs/guidance.md), written only for simulations that have
guidance sensors or a controller that estimates its pose:

==================================  ==========================  ================================
topic                               type                        when
==================================  ==========================  ================================
/<robot>/<line sensor>              std_msgs/Float64MultiArray  pose rate: the line's lateral
                                                                offset (m, left +) of each run
                                                                of lit elements, right to left
                                                                (empty: no line under the bar)
/<robot>/<line sensor>/spot         std_msgs/String             when the spot under the reader
                                                                changes: its code, "" for none
/<robot>/<floor camera>/fix         nav_msgs/Odometry           each fix: the pose a floor code
                                                                gave (map frame)
/<robot>/localization               nav_msgs/Odometry           pose rate: the pose the
                                                                controller estimates (map frame)
                                                                stamped with the time of the
                                                                observation it acted on
==================================  ==========================  ================================
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agvsim.record import ros2msg as msg
from agvsim.record.ros2msg import topic_name


class GuidanceTopics:
    """Writes the guidance topics of one simulation through ``recorder`` (a Recorder)."""

    def __init__(self, recorder: Any, sim: Any):
        self.rec, self.sim = recorder, sim
        rts = recorder.robot_topics
        g = sim.guidance
        self._lines: list[tuple[int, str]] = []
        self._fixes: list[tuple[int, str, msg.OdometryEncoder]] = []
        if g is not None:
            for k, spec in enumerate(g.line_specs):
                self._lines.append((k, f"/{rts[int(g.line_owner[k])]}/{topic_name(spec.name)}"))
            for c, spec in enumerate(g.cam_specs):
                rt = rts[int(g.cam_owner[c])]
                enc = msg.OdometryEncoder("map", f"{rt}/base_link")
                self._fixes.append((c, f"/{rt}/{topic_name(spec.name)}/fix", enc))
        self._last_spot = np.full(len(self._lines), -2, dtype=np.int64)
        self._last_fix = np.zeros(len(self._fixes), dtype=np.int64)
        #: robot index -> its controller, where the controller estimates the pose
        self._est = [
            (int(i), b.controller, msg.OdometryEncoder("map", f"{rts[int(i)]}/base_link"))
            for b in sim.bindings
            if not b.batch and hasattr(b.controller, "estimate")
            for i in b.robots
        ]

    @classmethod
    def needed(cls, sim: Any) -> bool:
        return getattr(sim, "guidance", None) is not None or any(
            not b.batch and hasattr(b.controller, "estimate") for b in sim.bindings
        )

    def write(self, t_ns: int) -> None:
        st, rec = self.sim.state, self.rec
        for n, (k, topic) in enumerate(self._lines):
            offs = st.line_offsets[k]
            values = offs[np.isfinite(offs)].tolist()
            rec._write(topic, msg.FLOAT64_MULTI_ARRAY, t_ns,
                       msg.encode_float64_multi_array("offset_m", values))  # fmt: skip
            spot = int(st.line_spot[k])
            if spot != self._last_spot[n]:
                self._last_spot[n] = spot
                text = "" if spot < 0 else str(spot)
                rec._write(f"{topic}/spot", msg.STRING, t_ns, msg.encode_string(text))
        for n, (c, topic, enc) in enumerate(self._fixes):
            if st.fix_seq[c] != self._last_fix[n]:
                self._last_fix[n] = st.fix_seq[c]
                stamp = int(round(float(st.fix_stamp[c]) * 1e9))
                data = enc.encode(stamp, st.fix_pose[c].tolist(), (0.0, 0.0, 0.0))
                rec._write(topic, msg.ODOMETRY, stamp, data)
        for i, ctrl, enc in self._est:
            est = getattr(ctrl, "estimate", None)
            if est is not None:  # stamped with the time of the observation it is of
                topic = f"/{rec.robot_topics[i]}/localization"
                stamp = int(round(float(getattr(ctrl, "estimate_stamp_s", t_ns * 1e-9)) * 1e9))
                data = enc.encode(stamp, [float(v) for v in est], (0.0, 0.0, 0.0))
                rec._write(topic, msg.ODOMETRY, stamp, data)
