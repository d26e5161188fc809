"""The ULX3S's pins for the serial wrapper and for the board design, and the ``.lpf`` that
places every port.

The pin sites and I/O standards come from amaranth-boards' ULX3S platform
(``amaranth_boards.ulx3s.ULX3S_85F_Platform`` and its 25F and 45F siblings, the same board).
The serial wrapper (:data:`ULX3S_PINS`): the 25 MHz oscillator (resource ``clk25``), the
FIRE 1 button (``button_fire`` 0) as reset, and four pins of the GPIO header (connector
``gpio`` 0, pins ``0+`` .. ``3+``: the board's ``gp[0]`` .. ``gp[3]``). The board design
(:data:`ULX3S_BOARD_PINS`, :class:`raplas_hdl.rtl.ulx3s_top.ULX3STop`): the oscillator, the
button, the FTDI's serial lines (resource ``uart`` 0, subsignals ``rx`` and ``tx``) and
LEDs 0-5 (resource ``led``). amaranth-boards gives the header pins no attributes; the header's
banks are powered at 3.3 V on the ULX3S, so they are ``LVCMOS33``, inputs pulled down (an
unconnected header idles with ``sclk`` and ``load`` low), the output at 4 mA.

:func:`lpf_text` writes one ``LOCATE COMP`` and one ``IOBUF PORT`` line per port and a
``FREQUENCY PORT`` line for the clock, so that nextpnr is left nothing to choose;
:func:`check_lpf` reads the file back and fails naming any port of the design it does not
place (or any it names that the design lacks).
"""

from __future__ import annotations

import re

__all__ = ["BOARD", "ULX3S_PINS", "ULX3S_BOARD_PINS", "HEADER_ATTRS", "ulx3s_pins", "lpf_text",
           "lpf_ports", "check_lpf"]

BOARD = "ULX3S"

#: Wrapper port -> its place on the board: ``("resource", name, number)`` of the platform,
#: ``("resource", name, number, subsignal)``, or ``("connector", name, number, pin)``.
ULX3S_PINS = {
    "clk_25mhz": ("resource", "clk25", 0),
    "rst": ("resource", "button_fire", 0),
    "sclk": ("connector", "gpio", 0, "0+"),
    "sdi": ("connector", "gpio", 0, "1+"),
    "load": ("connector", "gpio", 0, "2+"),
    "sdo": ("connector", "gpio", 0, "3+"),
}

#: The board design's ports (:class:`raplas_hdl.rtl.ulx3s_top.ULX3STop`) -> their places.
ULX3S_BOARD_PINS = {
    "clk_25mhz": ("resource", "clk25", 0),
    "btn_fire": ("resource", "button_fire", 0),
    "uart_rx": ("resource", "uart", 0, "rx"),
    "uart_tx": ("resource", "uart", 0, "tx"),
    **{f"led_{name}": ("resource", "led", k) for k, name in
       enumerate(("heartbeat", "rx", "tx", "bus", "bus_error", "locked"))},
}

#: Attributes of the GPIO header pins (amaranth-boards gives none), by direction.
HEADER_ATTRS = {"input": {"IO_TYPE": "LVCMOS33", "PULLMODE": "DOWN"},
                "output": {"IO_TYPE": "LVCMOS33", "DRIVE": "4"}}

_PLATFORMS = {"LFE5U-25F": "ULX3S_25F_Platform", "LFE5U-45F": "ULX3S_45F_Platform",
              "LFE5U-85F": "ULX3S_85F_Platform"}


def _platform(device: str):
    try:
        from amaranth_boards import ulx3s
    except ModuleNotFoundError:
        raise ValueError("the ULX3S pin file comes from amaranth-boards: pip install "
                         "amaranth-boards (pinned in requirements.lock)") from None
    if device not in _PLATFORMS:
        raise ValueError(f"the ULX3S comes with {', '.join(_PLATFORMS)}, not {device}")
    return getattr(ulx3s, _PLATFORMS[device])()


def ulx3s_pins(device: str = "LFE5U-85F", directions: dict | None = None,
               places: dict | None = None) -> dict:
    """``{port: {"site", "attrs", "from", "mhz"}}`` of ``places`` (default
    :data:`ULX3S_PINS`) on the ULX3S with ``device``. ``directions``
    (``{port: "input" | "output"}``) picks the header pins' attributes (default: ``sdo``
    out, the rest in)."""
    plat = _platform(device)
    directions = directions or {}
    out = {}
    for port, where in (ULX3S_PINS if places is None else places).items():
        if where[0] == "resource":
            name, number, sub = where[1], where[2], where[3] if len(where) > 3 else None
            res = plat.resources[name, number]
            attrs = {k: str(v) for k, v in res.attrs.items()}
            pins, what = res.ios[0], f"{name} {number}"
            if sub is not None:
                subs = {s.name: s for s in res.ios}
                if sub not in subs:
                    raise ValueError(f"resource {name} {number} has no subsignal {sub}")
                attrs.update({k: str(v) for k, v in subs[sub].attrs.items()})
                pins, what = subs[sub].ios[0], f"{name} {number} {sub}"
            if len(getattr(pins, "names", ())) != 1 or getattr(pins, "invert", False):
                raise ValueError(f"resource {what} is not one plain pin")
            mhz = res.clock.frequency / 1e6 if res.clock is not None else None
            out[port] = {"site": pins.names[0], "attrs": attrs, "from": what, "mhz": mhz}
        else:
            _, name, number, pin = where
            site = plat.connectors[name, number].mapping[pin]
            way = directions.get(port, "output" if port == "sdo" else "input")
            out[port] = {"site": site, "attrs": dict(HEADER_ATTRS[way]),
                         "from": f"connector {name} {number} pin {pin}", "mhz": None}
    return out


def lpf_text(ports: list[dict], pins: dict, title: str) -> str:
    """The ``.lpf`` placing ``ports`` (``[{"name", "direction", "width"}]``, the emitted
    top's) on ``pins`` (:func:`ulx3s_pins`). ``ValueError`` for a port with no pin or wider
    than one bit."""
    lines = [f"# {title}", "# Generated by raplas-hdl (raplas_hdl/pnr/board.py) from "
             "amaranth-boards' ULX3S platform; do not edit.", "BLOCK RESETPATHS;",
             "BLOCK ASYNCPATHS;"]
    for p in ports:
        name = p["name"]
        if p["width"] != 1:
            raise ValueError(f"port {name} is {p['width']} bits wide: the board file places "
                             "one-bit ports only")
        if name not in pins:
            raise ValueError(f"port {name} has no pin on the {BOARD} (pins for: "
                             f"{', '.join(pins)})")
        pin = pins[name]
        attrs = " ".join(f"{k}={v}" for k, v in pin["attrs"].items())
        lines += [f'LOCATE COMP "{name}" SITE "{pin["site"]}";  # {pin["from"]}',
                  f'IOBUF PORT "{name}" {attrs};']
        if pin["mhz"]:
            lines.append(f'FREQUENCY PORT "{name}" {pin["mhz"]:g} MHZ;')
    return "\n".join(lines) + "\n"


_LOCATE = re.compile(r'^\s*LOCATE\s+COMP\s+"([^"]+)"\s+SITE\s+"([^"]+)"\s*;', re.M)
_IOBUF = re.compile(r'^\s*IOBUF\s+PORT\s+"([^"]+)"\s+([^;]*);', re.M)
_FREQ = re.compile(r'^\s*FREQUENCY\s+PORT\s+"([^"]+)"\s+([0-9.]+)\s*MHZ\s*;', re.M | re.I)


def lpf_ports(text: str) -> dict:
    """``{"locate": {port: site}, "iobuf": {port: attrs}, "frequency": {port: MHz}}``."""
    return {"locate": dict(_LOCATE.findall(text)), "iobuf": dict(_IOBUF.findall(text)),
            "frequency": {k: float(v) for k, v in _FREQ.findall(text)}}


def check_lpf(text: str, ports: list[dict], clock: str) -> dict:
    """``ValueError`` unless every port of ``ports`` has a site and an I/O standard, no two
    share a site, nothing else is named, and ``clock`` has a frequency; returns
    :func:`lpf_ports`."""
    got = lpf_ports(text)
    names = {p["name"] for p in ports}
    for what, placed in (("LOCATE COMP", got["locate"]), ("IOBUF PORT", got["iobuf"])):
        missing = sorted(names - set(placed))
        if missing:
            raise ValueError(f"the .lpf has no {what} line for port(s) {', '.join(missing)}")
        extra = sorted(set(placed) - names)
        if extra:
            raise ValueError(f"the .lpf names port(s) the design lacks: {', '.join(extra)}")
    sites = list(got["locate"].values())
    shared = sorted({s for s in sites if sites.count(s) > 1})
    if shared:
        raise ValueError(f"the .lpf puts two ports on site(s) {', '.join(shared)}")
    if any("IO_TYPE=" not in a for a in got["iobuf"].values()):
        raise ValueError("the .lpf leaves a port without an IO_TYPE")
    if clock not in got["frequency"]:
        raise ValueError(f"the .lpf gives the clock {clock} no FREQUENCY")
    return got
