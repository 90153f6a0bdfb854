"""The emulated flight controller on the firmware's UART: what it sends (generated with
pymavlink) and where, given the frame's truth, it expects the firmware's LANDING_TARGET.

- `ardupilot`: HEARTBEAT (MAV_AUTOPILOT_ARDUPILOTMEGA) at 1 Hz, nothing else: the ArduPilot
  profile needs no vehicle state (ArduPilot takes the pad in MAV_FRAME_BODY_FRD and applies
  its own attitude).
- `px4`: HEARTBEAT (MAV_AUTOPILOT_PX4) and SYSTEM_TIME at 1 Hz, TIMESYNC requests at 10 Hz,
  ATTITUDE_QUATERNION and
  LOCAL_POSITION_NED at 50 Hz (what the firmware asks for with SET_MESSAGE_INTERVAL), the
  vehicle hovering level at a fixed point, heading 30 degrees, its clock 100 s ahead of the
  firmware's: PX4 takes a position only in MAV_FRAME_LOCAL_NED, so the firmware must turn the
  pad into the vehicle's local frame with this state (docs/interfaces.md, "MAVLink").
The autopilot does not answer the firmware: its TIMESYNC requests go unanswered, and the
firmware aligns the clocks on SYSTEM_TIME, as it does until a first answer. The firmware must
answer PX4's TIMESYNC requests, within PX4's 10 ms (fil.py checks it).
"""

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

AUTOPILOT_SYSID = 1
HEARTBEAT_PERIOD_NS = 1e9
STATE_PERIOD_NS = 20e6
# The PX4 vehicle: NED position (m), heading (rad), and how long it has been up (ms).
PX4_POSITION = (12.0, -7.0, -4.04)
PX4_YAW = math.radians(30.0)
PX4_BOOTED_BEFORE_MS = 100_000
# PX4's TIMESYNC requests: about 10 Hz, its onboard mode's rate (src/modules/mavlink/
# mavlink_main.cpp, configure_streams_to_default), the first this long after the schedule's
# start (not queued behind the HEARTBEAT and SYSTEM_TIME on the line). Not exactly 100 ms:
# that is three frame periods, and every request would meet the frame processing at the same
# point; 103.7 ms moves 3.7 ms further into a frame each time, so two seconds cover all of it.
TIMESYNC_PERIOD_NS = 103.7e6
TIMESYNC_AFTER_NS = 0.5e6
# PX4 uses a TIMESYNC answer only if it came back within this (src/lib/timesync/Timesync.hpp,
# MAX_RTT_SAMPLE): the companion must answer within it.
PX4_MAX_RTT_NS = 10e6
KINDS = ("ardupilot", "px4")


class Autopilot:
    """One emulated flight controller of `kind` (KINDS)."""

    def __init__(self, kind):
        self.kind = kind
        self.mav = mavlink.MAVLink(None, srcSystem=AUTOPILOT_SYSID, srcComponent=1)
        # PX4's TIMESYNC requests: (emulated time ns it sent one, its ts1).
        self.timesync_requests = []

    def heartbeat(self):
        autopilot = mavlink.MAV_AUTOPILOT_PX4 if self.kind == "px4" else \
            mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        return self.mav.heartbeat_encode(
            mavlink.MAV_TYPE_QUADROTOR, autopilot, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            0, mavlink.MAV_STATE_ACTIVE).pack(self.mav)

    def feed(self, machine, start_ns, end_ns, extra=()):
        """Puts what the autopilot sends from `start_ns` to `end_ns`, and the `(time ns,
        bytes)` of `extra`, on the firmware's receive line, in time order (the line queues what
        it is fed)."""
        sends = list(extra)
        t = start_ns
        while t < end_ns:
            sends.append((t, self.heartbeat()))
            if self.kind == "px4":
                sends.append((t, self.mav.system_time_encode(
                    1_700_000_000_000_000 + int(t / 1e3), self._boot_ms(t)).pack(self.mav)))
            t += HEARTBEAT_PERIOD_NS
        if self.kind == "px4":
            t = start_ns
            while t < end_ns:
                sends += [(t, self._attitude(t)), (t, self._position(t))]
                t += STATE_PERIOD_NS
            # PX4 asks for the companion's time (tc1 = 0, ts1 = its own, ns).
            t = start_ns + TIMESYNC_AFTER_NS
            while t < end_ns:
                ts1 = int(t) + PX4_BOOTED_BEFORE_MS * 1_000_000
                self.timesync_requests.append((t, ts1))
                sends.append((t, self.mav.timesync_encode(0, ts1).pack(self.mav)))
                t += TIMESYNC_PERIOD_NS
        for at, data in sorted(sends, key=lambda send: send[0]):
            machine.uart.feed(data, at)

    @staticmethod
    def _boot_ms(t_ns):
        return int(t_ns / 1e6) + PX4_BOOTED_BEFORE_MS

    def _attitude(self, t_ns):
        half = PX4_YAW / 2
        return self.mav.attitude_quaternion_encode(
            self._boot_ms(t_ns), math.cos(half), 0.0, 0.0, math.sin(half), 0.0, 0.0, 0.0,
            [0.0, 0.0, 0.0, 0.0]).pack(self.mav)

    def _position(self, t_ns):
        north, east, down = PX4_POSITION
        return self.mav.local_position_ned_encode(
            self._boot_ms(t_ns), north, east, down, 0.0, 0.0, 0.0).pack(self.mav)

    def expected_target(self, truth, scale=1.0):
        """The pad centre as the firmware should report it for the frame's `truth` (the pad
        printed at `scale` times its built size: the pad, as the firmware sees it, `scale`
        times as far), with the frame it should use and the pad's distance.

        Through the camera mount (looking down, image top toward the nose): body x forward =
        -camera y, body y right = camera x, body z down = camera z; angle_x/angle_y are the
        target's angles from the optical axis along the image's x and y (unscaled). PX4: the
        body vector turned by the heading and added to the vehicle's local position."""
        cx, cy, cz = (scale * truth[k] for k in ("pad_cam_x", "pad_cam_y", "pad_cam_z"))
        body = (-cy, cx, cz)
        want = {"frame": mavlink.MAV_FRAME_BODY_FRD, "x": body[0], "y": body[1], "z": body[2],
                "distance": math.sqrt(cx * cx + cy * cy + cz * cz),
                "angle_x": math.atan2(cx, cz), "angle_y": math.atan2(cy, cz)}
        if self.kind == "px4":
            c, s = math.cos(PX4_YAW), math.sin(PX4_YAW)
            north, east, down = PX4_POSITION
            want.update(frame=mavlink.MAV_FRAME_LOCAL_NED,
                        x=north + c * body[0] - s * body[1],
                        y=east + s * body[0] + c * body[1], z=down + body[2])
        return want
