"""The emulated flight controller on the firmware's UART: what it sends (generated with
pymavlink) and where, given the frame's truth, it expects the firmware's LANDING_TARGET.

The vehicle it reports is the one the frame was rendered from: the truth file (make_frame.py)
gives the camera's position over the pad and the vehicle's attitude at the frame (the frame
was rendered with the nominal camera mount), so the attitude and position the firmware is
told agree with what it sees. The world is then turned 30 degrees about the vertical and its
local origin moved (LOCAL_ORIGIN_NED): a heading or an origin the firmware ignored would show.

- `ardupilot`: HEARTBEAT (MAV_AUTOPILOT_ARDUPILOTMEGA) at 1 Hz and ATTITUDE_QUATERNION at
  50 Hz (the rate the firmware asks for with SET_MESSAGE_INTERVAL; its rolling-shutter
  correction and the pose's levelling use it). The ArduPilot profile needs no more: ArduPilot
  takes the pad in MAV_FRAME_BODY_FRD and applies its own attitude.
- `ardupilot-4.7`: the same, and at the start a PARAM_SET of TD_PROFILE 3 (the set-up guide's
  step for ArduPilot 4.7 and later): the pad in MAV_FRAME_LOCAL_FRD, levelled with the
  attitude and turned with the heading.
- `px4`: HEARTBEAT (MAV_AUTOPILOT_PX4) and SYSTEM_TIME at 1 Hz, TIMESYNC requests at about
  10 Hz, ATTITUDE_QUATERNION and LOCAL_POSITION_NED at 50 Hz, its clock 100 s ahead of the
  firmware's: PX4 takes a position only in MAV_FRAME_LOCAL_NED, so the firmware must turn the
  pad into the vehicle's local frame with this state (docs/interfaces.md, "MAVLink").
With `line_noise` (`--line-noise`) a quarter of its messages come after 1 to 40 bytes of
garbage, often holding a MAVLink start byte: the firmware must resynchronise and lose only
those messages. The autopilot does not answer the firmware: its TIMESYNC requests go unanswered, and the
firmware aligns the clocks on SYSTEM_TIME, as it does until a first answer. The firmware must
answer PX4's TIMESYNC requests quickly (fil.py checks it).
"""

import math
import random

from pymavlink.dialects.v20 import ardupilotmega as mavlink

AUTOPILOT_SYSID = 1
HEARTBEAT_PERIOD_NS = 1e9
STATE_PERIOD_NS = 20e6
# The world's turn about the vertical (rad) and where the pad lies in the local NED frame (m).
WORLD_YAW = math.radians(30.0)
LOCAL_ORIGIN_NED = (12.0, -7.0, 0.0)
# How long the autopilot has been up when the firmware starts (ms: its clock).
BOOTED_BEFORE_MS = 100_000
# The firmware's MAVLink ids (TD_SYSID / TD_COMPID defaults, docs/interfaces.md).
FIRMWARE_SYSID, FIRMWARE_COMPID = 1, 191
# Line noise (`--line-noise`): the share of messages preceded by garbage, and its seed.
LINE_NOISE_SHARE = 0.25
LINE_NOISE_SEED = 7
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


def quaternion_product(a, b):
    """a * b for unit quaternions (w, x, y, z): the rotation b, then a."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def rotate(q, v):
    """v turned by the unit quaternion q = (w, x, y, z)."""
    w, x, y, z = q
    return (
        (1 - 2 * (y * y + z * z)) * v[0] + 2 * (x * y - w * z) * v[1] + 2 * (x * z + w * y) * v[2],
        2 * (x * y + w * z) * v[0] + (1 - 2 * (x * x + z * z)) * v[1] + 2 * (y * z - w * x) * v[2],
        2 * (x * z - w * y) * v[0] + 2 * (y * z + w * x) * v[1] + (1 - 2 * (x * x + y * y)) * v[2],
    )


class Autopilot:
    """One emulated flight controller of `kind` ("ardupilot", "ardupilot-4.7" or "px4") over the vehicle of the frame's
    `truth` (read_truth: pad_cam_*, cam_*, veh_q*)."""

    def __init__(self, kind, truth, line_noise=False):
        self.kind = kind
        self.profile_set = False
        # Garbage on the line between the messages (see `_noise`).
        self.noise = random.Random(LINE_NOISE_SEED) if line_noise else None
        # Messages fed, and garbage (messages preceded, bytes) put before them.
        self.fed, self.garbled, self.garbage_bytes = 0, 0, 0
        self.truth = truth
        self.mav = mavlink.MAVLink(None, srcSystem=AUTOPILOT_SYSID, srcComponent=1)
        # Its clock at the schedule's time 0, ms (a reboot sets it so that the clock restarts
        # from zero), and whether its HEARTBEAT says armed (soak.py changes both).
        self.booted_before_ms = BOOTED_BEFORE_MS
        self.armed = False
        # PX4's TIMESYNC requests: (emulated time ns it sent one, its ts1).
        self.timesync_requests = []
        turn = (math.cos(WORLD_YAW / 2), 0.0, 0.0, math.sin(WORLD_YAW / 2))
        # Body FRD to local NED; the frame's NED has north = pad +y, east = pad +x.
        self.attitude = quaternion_product(
            turn, tuple(truth[f"veh_q{k}"] for k in "wxyz"))
        camera_ned = (truth["cam_y"], truth["cam_x"], -truth["cam_z"])
        self.position = tuple(o + c for o, c in zip(LOCAL_ORIGIN_NED, rotate(turn, camera_ned)))

    def heartbeat(self):
        autopilot = mavlink.MAV_AUTOPILOT_PX4 if self.kind == "px4" else \
            mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        base_mode = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            base_mode |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        return self.mav.heartbeat_encode(
            mavlink.MAV_TYPE_QUADROTOR, autopilot, base_mode, 0,
            mavlink.MAV_STATE_ACTIVE).pack(self.mav)

    def sets_parameters(self):
        """Whether this autopilot changes a parameter of the firmware (which the firmware then
        saves to flash)."""
        return self.kind == "ardupilot-4.7"

    def feed(self, machine, start_ns, end_ns, extra=()):
        """Puts what the autopilot sends from `start_ns` to `end_ns`, and the `(time ns,
        bytes)` of `extra`, on the firmware's receive line, in time order (the line queues what
        it is fed)."""
        sends = list(extra)
        if self.sets_parameters() and not self.profile_set:
            # The set-up guide's step for ArduPilot 4.7 and later: TD_PROFILE 3 (LOCAL_FRD).
            self.profile_set = True
            sends.append((start_ns, self.mav.param_set_encode(
                FIRMWARE_SYSID, FIRMWARE_COMPID, b"TD_PROFILE", 3.0,
                mavlink.MAV_PARAM_TYPE_REAL32).pack(self.mav)))
        t = start_ns
        while t < end_ns:
            sends.append((t, self.heartbeat()))
            if self.kind == "px4":
                sends.append((t, self.mav.system_time_encode(
                    1_700_000_000_000_000 + int(t / 1e3), self._boot_ms(t)).pack(self.mav)))
            t += HEARTBEAT_PERIOD_NS
        t = start_ns
        while t < end_ns:
            sends.append((t, self._attitude(t)))
            if self.kind == "px4":
                sends.append((t, self._position(t)))
            t += STATE_PERIOD_NS
        if self.kind == "px4":
            # PX4 asks for the companion's time (tc1 = 0, ts1 = its own, ns).
            t = start_ns + TIMESYNC_AFTER_NS
            while t < end_ns:
                ts1 = int(t) + BOOTED_BEFORE_MS * 1_000_000
                self.timesync_requests.append((t, ts1))
                sends.append((t, self.mav.timesync_encode(0, ts1).pack(self.mav)))
                t += TIMESYNC_PERIOD_NS
        for at, data in sorted(sends, key=lambda send: send[0]):
            machine.uart.feed(self._noise() + data, at)

    def _noise(self):
        """With line noise: before about one message in four, 1 to 40 random bytes, often
        with a MAVLink start byte among them (a frame that starts and never ends, or whose CRC
        fails); nothing otherwise."""
        self.fed += 1
        if self.noise is None or self.noise.random() > LINE_NOISE_SHARE:
            return b""
        garbage = bytearray(self.noise.randbytes(self.noise.randint(1, 40)))
        if self.noise.random() < 0.5:
            garbage[self.noise.randrange(len(garbage))] = self.noise.choice((0xFD, 0xFE))
        self.garbled += 1
        self.garbage_bytes += len(garbage)
        return bytes(garbage)

    def _boot_ms(self, t_ns):
        return int(t_ns / 1e6) + self.booted_before_ms

    def _attitude(self, t_ns):
        w, x, y, z = self.attitude
        return self.mav.attitude_quaternion_encode(
            self._boot_ms(t_ns), w, x, y, z, 0.0, 0.0, 0.0, [0.0, 0.0, 0.0, 0.0]).pack(self.mav)

    def _position(self, t_ns):
        north, east, down = self.position
        return self.mav.local_position_ned_encode(
            self._boot_ms(t_ns), north, east, down, 0.0, 0.0, 0.0).pack(self.mav)

    def expected_target(self, scale=1.0, depth_scale=1.0):
        """The pad centre as the firmware should report it (the pad printed at `scale` times
        its built size: the pad, as the firmware sees it, `scale` times as far; through a lens
        `depth_scale` times longer than the frame's: `depth_scale` times as deep along the
        optical axis, unmoved across it), with the frame it should use and the pad's distance.

        Through the nominal camera mount (looking down, image top toward the nose): body x
        forward = -camera y, body y right = camera x, body z down = camera z; angle_x/angle_y
        are the target's angles from the optical axis along the image's x and y (unscaled).
        PX4: the body vector turned into the local frame and added to the vehicle's position
        (with `scale` 1, the pad's own position, LOCAL_ORIGIN_NED, up to rounding)."""
        truth = self.truth
        cx, cy, cz = (scale * truth[k] for k in ("pad_cam_x", "pad_cam_y", "pad_cam_z"))
        cz *= depth_scale
        body = (-cy, cx, cz)
        want = {"frame": mavlink.MAV_FRAME_BODY_FRD, "x": body[0], "y": body[1], "z": body[2],
                "distance": math.sqrt(cx * cx + cy * cy + cz * cz),
                "angle_x": math.atan2(cx, cz), "angle_y": math.atan2(cy, cz)}
        if self.kind == "px4":
            ned = rotate(self.attitude, body)
            x, y, z = (p + d for p, d in zip(self.position, ned))
            want.update(frame=mavlink.MAV_FRAME_LOCAL_NED, x=x, y=y, z=z)
        elif self.kind == "ardupilot-4.7":
            # Levelled: turned into NED with the whole attitude, then back by the heading alone.
            north, east, down = rotate(self.attitude, body)
            w, qx, qy, qz = self.attitude
            heading = math.atan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
            c, s = math.cos(heading), math.sin(heading)
            x, y = c * north + s * east, -s * north + c * east
            want.update(frame=mavlink.MAV_FRAME_LOCAL_FRD, x=x, y=y, z=down,
                        angle_x=math.atan2(y, down), angle_y=math.atan2(-x, down))
        return want
