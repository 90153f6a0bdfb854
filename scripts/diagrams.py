#!/usr/bin/env python3
"""Writes the documentation's two drawn diagrams as SVG (standard library only).

    python3 scripts/diagrams.py wiring OUT.svg     the camera board to the flight controller
    python3 scripts/diagrams.py pipeline OUT.svg   the per-frame path on the camera board

The pins are those of firmware/README.md's wiring tables (which say which are checked
against ST's pin data and which are board-level details to check); the stages are those of
core::pipeline and core::detect. Change those first, then this drawing.
"""

import sys
from xml.sax.saxutils import escape

FONT = "font-family=\"DejaVu Sans, Helvetica, Arial, sans-serif\""


class Svg:
    def __init__(self, width, height):
        self.width, self.height = width, height
        self.items = []

    def box(self, x, y, w, h, fill="#ffffff", stroke="#333333", rx=6):
        self.items.append(
            f'<rect x="{x}" y="{y}" width="{w}" height="{h}" rx="{rx}" '
            f'fill="{fill}" stroke="{stroke}" stroke-width="1.5"/>'
        )

    def text(self, x, y, s, size=13, anchor="start", weight="normal", fill="#111111"):
        self.items.append(
            f'<text x="{x}" y="{y}" font-size="{size}" text-anchor="{anchor}" '
            f'font-weight="{weight}" fill="{fill}" {FONT}>{escape(s)}</text>'
        )

    def line(self, x1, y1, x2, y2, stroke="#333333", width=2, arrow=False, dash=None):
        extra = ' marker-end="url(#arrow)"' if arrow else ""
        if dash:
            extra += f' stroke-dasharray="{dash}"'
        self.items.append(
            f'<line x1="{x1}" y1="{y1}" x2="{x2}" y2="{y2}" stroke="{stroke}" '
            f'stroke-width="{width}"{extra}/>'
        )

    def path(self, d, stroke="#333333", width=2, arrow=False, dash=None):
        extra = ' marker-end="url(#arrow)"' if arrow else ""
        if dash:
            extra += f' stroke-dasharray="{dash}"'
        self.items.append(
            f'<path d="{d}" fill="none" stroke="{stroke}" stroke-width="{width}"{extra}/>'
        )

    def render(self):
        head = (
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{self.width}" '
            f'height="{self.height}" viewBox="0 0 {self.width} {self.height}">\n'
            '<defs><marker id="arrow" viewBox="0 0 10 10" refX="9" refY="5" '
            'markerUnits="userSpaceOnUse" markerWidth="11" markerHeight="11" orient="auto-start-reverse">'
            '<path d="M0,0 L10,5 L0,10 z" fill="#333333"/></marker></defs>\n'
            f'<rect width="{self.width}" height="{self.height}" fill="#ffffff"/>\n'
        )
        return head + "\n".join(self.items) + "\n</svg>\n"


def wiring():
    svg = Svg(900, 470)
    svg.text(450, 28, "Camera board to flight controller: MAVLink 2, 3.3 V logic, TX and RX crossed",
             size=15, anchor="middle", weight="bold")

    # The camera board.
    svg.box(30, 60, 330, 250, fill="#eef4fb")
    svg.text(195, 85, "camera board (STM32H743)", size=14, anchor="middle", weight="bold")
    svg.text(195, 105, "NUCLEO-H743ZI2  |  OpenMV Cam H7", size=12, anchor="middle")
    rows = [
        (150, "PG14 (D1), USART6_TX", "P4 = PB10, USART3_TX", "TX"),
        (200, "PG9 (D0), USART6_RX", "P5 = PB11, USART3_RX", "RX"),
        (250, "GND", "GND", "GND"),
    ]
    for y, nucleo, openmv, name in rows:
        svg.text(45, y - 4, nucleo, size=12)
        svg.text(45, y + 12, openmv, size=12, fill="#555555")
        svg.text(345, y + 4, name, size=13, anchor="end", weight="bold")

    # The flight controller's TELEM2.
    svg.box(540, 60, 330, 250, fill="#f6f1e7")
    svg.text(705, 85, "flight controller TELEM2", size=14, anchor="middle", weight="bold")
    svg.text(705, 105, "6-pin JST-GH, Pixhawk standard", size=12, anchor="middle")
    pins = [
        (125, "pin 1, 5 V: leave unconnected (board on USB)", "#888888"),
        (150, "pin 3, RX", "#111111"),
        (200, "pin 2, TX", "#111111"),
        (250, "pin 6, GND", "#111111"),
        (275, "pins 4, 5 (RTS, CTS): not wired, flow control off", "#888888"),
    ]
    for y, label, colour in pins:
        svg.text(555, y + 4, label, size=12, fill=colour)

    colours = {"TX": "#1f6fbf", "RX": "#c0392b", "GND": "#222222"}
    svg.line(360, 150, 540, 150, stroke=colours["TX"], width=3, arrow=True)
    svg.line(540, 200, 360, 200, stroke=colours["RX"], width=3, arrow=True)
    svg.line(360, 250, 540, 250, stroke=colours["GND"], width=3)
    svg.text(450, 143, "board TX to autopilot RX", size=11, anchor="middle", fill=colours["TX"])
    svg.text(450, 193, "autopilot TX to board RX", size=11, anchor="middle", fill=colours["RX"])

    # The camera (NUCLEO with a module; the OpenMV Cam has its OV7725 on board).
    svg.box(30, 340, 840, 110, fill="#f4f4f4")
    svg.text(45, 362, "camera module (NUCLEO only; the OpenMV Cam H7 has its OV7725 on board): "
             "OV7725 or OV2640, 8-bit DCMI", size=12, weight="bold")
    svg.text(45, 384, "D0-D7: PC6, PC7, PE0, PC9, PE4, PB6, PE5, PE6; PIXCLK: PA6; "
             "HSYNC: PA4; VSYNC: PB7", size=12)
    svg.text(45, 404, "SCCB (I2C1): SCL PB8, SDA PB9, 4.7 kOhm pull-ups; XCLK: PA8 (MCO1); "
             "RESET: PD4; PWDN: PD7", size=12)
    svg.text(45, 430, "Pin table with alternate functions and the items still to check "
             "against the board: firmware/README.md, \"Wiring\"", size=11, fill="#555555")
    return svg.render()


def pipeline():
    svg = Svg(940, 400)
    svg.text(470, 28, "One frame on the camera board (core::pipeline::FramePipeline, then the companion)",
             size=15, anchor="middle", weight="bold")

    def stage(x, y, w, h, title, lines, fill):
        svg.box(x, y, w, h, fill=fill)
        svg.text(x + w / 2, y + 22, title, size=14, anchor="middle", weight="bold")
        for k, line in enumerate(lines):
            svg.text(x + 10, y + 44 + 17 * k, line, size=11.5)

    stage(20, 60, 150, 150, "camera", ["OV7725 / OV2640", "DCMI + DMA into", "two frame buffers",
                                         "grey (Y of YUV)"], "#f4f4f4")
    stage(200, 60, 220, 250, "detection", ["1 local threshold", "2 boundary following",
                                             "3 screening, Douglas-Peucker,", "   a quick look",
                                             "4 sub-pixel edges", "5 decoding, error correction",
                                             "6 de-duplication", "7 pattern fit of a far marker",
                                             "one work budget per frame"], "#eef4fb")
    stage(450, 60, 200, 200, "pad fix", ["rolling-shutter correction", "every marker's corners:",
                                           "IPPE + Levenberg-Marquardt", "level fix (attitude at",
                                           "the exposure)", "flip choice by prediction",
                                           "the mount's roll and pitch"], "#eef4fb")
    stage(680, 60, 240, 150, "estimator and companion", ["3-D tracker (Kalman filter)",
                                                          "LANDING_TARGET, MAVLink 2",
                                                          "ArduPilot: body FRD vector", "PX4: LOCAL_NED position",
                                                          "TIMESYNC, parameters"], "#eef4fb")
    svg.box(680, 290, 240, 60, fill="#f6f1e7")
    svg.text(800, 315, "autopilot", size=14, anchor="middle", weight="bold")
    svg.text(800, 335, "ArduPilot or PX4, over the UART", size=11.5, anchor="middle")

    svg.line(170, 130, 200, 130, arrow=True)
    svg.line(420, 130, 450, 130, arrow=True)
    svg.line(650, 130, 680, 130, arrow=True)
    svg.line(780, 210, 780, 290, arrow=True)
    svg.text(772, 255, "targets", size=11, anchor="end")
    # What the autopilot streams back: the attitude, position and clock at each exposure.
    svg.line(860, 290, 860, 212, arrow=True, dash="5,4")
    svg.text(868, 255, "attitude,", size=11)
    svg.text(868, 270, "position", size=11)
    svg.path("M 680 180 L 665 180 L 665 235 L 652 235", arrow=True, dash="5,4")
    svg.text(665, 250, "attitude", size=11, anchor="middle")
    # Exposure loop from the decoded markers back to the sensor.
    svg.path("M 310 310 L 310 335 L 95 335 L 95 212", arrow=True, dash="6,4")
    svg.text(105, 355, "auto-exposure: metered on the decoded markers' white and black,",
             size=11)
    svg.text(105, 371, "written to the sensor over SCCB", size=11)
    return svg.render()


def main(argv):
    if len(argv) != 3 or argv[1] not in ("wiring", "pipeline"):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    text = wiring() if argv[1] == "wiring" else pipeline()
    with open(argv[2], "w", encoding="utf-8") as f:
        f.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
