"""A meshcat window that records the scene in process (no server, no sockets) and writes the static page.

:class:`SceneRecorder` implements what :class:`meshcat.Visualizer` needs from its window with the
same bookkeeping as meshcat's ZMQ server, and produces the same self-contained page as
``Visualizer.static_html()`` (meshcat's JavaScript inlined, so the page opens offline);
:meth:`SceneRecorder.replay` sends the recorded commands to a live meshcat server.
"""

from __future__ import annotations

import base64
import html as html_mod
import warnings
from pathlib import Path
from typing import Any

from pin_kpi_oed.errors import PinKpiOedError


def import_meshcat():
    """meshcat, imported without its pyzmq DeprecationWarning (zmq.eventloop.ioloop, harmless)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
        import meshcat.visualizer  # noqa: F401
    return meshcat


def _command_js(data: bytes) -> str:
    """A drawing command for the static page (as meshcat's server writes it)."""
    return ('\nfetch("data:application/octet-binary;base64,{}")\n    .then(res => res.arrayBuffer())\n'
            '    .then(buffer => viewer.handle_command_bytearray(new Uint8Array(buffer)));\n'
            ).format(base64.b64encode(data).decode("ascii"))


class _Lowered:
    """A command already lowered to a dict (for replaying into another window)."""

    def __init__(self, d: dict) -> None:
        self.d = d

    def lower(self) -> dict:
        return self.d


class SceneRecorder:
    """A meshcat window that keeps the scene tree in process (no server, no sockets).

    It implements what :class:`meshcat.Visualizer` needs from its window (``send``,
    ``get_scene``, ``get_image``, ``open``, ``close``) with the same bookkeeping as
    meshcat's ZMQ server (``meshcat.servers.zmqserver``): ``set_object`` replaces a
    node's object and clears its properties, ``set_transform`` / ``set_property`` /
    ``delete`` act on the tree. :meth:`get_scene` writes the same self-contained page as
    the server (``main.min.js`` inlined), except that animations come last so that
    they bind to the objects they animate.

    Attributes:
        commands: every command received, lowered (dicts), in order.
    """

    web_url = None

    def __init__(self) -> None:
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()
        self.commands: list[dict] = []
        self.animation: bytes | None = None

    def send(self, command: Any) -> None:
        """Apply a meshcat command to the tree (and record it)."""
        import umsgpack
        from meshcat.servers.tree import SceneTree, find_node

        d = command.lower()
        self.commands.append(d)
        kind = d["type"]
        path = [p for p in str(d.get("path", "")).split("/") if p]
        data = umsgpack.packb(d)
        if kind == "set_animation":
            self.animation = data
            return
        if kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()
            return
        node = find_node(self.tree, path)
        if kind == "set_object":
            node.object, node.properties = data, []
        elif kind == "set_transform":
            node.transform = data
        elif kind == "set_property":
            node.properties.append(data)

    def get_scene(self, title: str = "MeshCat", extra_body: str = "") -> str:
        """The static page: meshcat's viewer and the scene's drawing commands."""
        import meshcat
        from meshcat.servers.tree import walk

        VIEWER_ROOT = Path(meshcat.__file__).resolve().parent / "viewer" / "dist"  # as meshcat.servers.zmqserver

        cmds = []
        for node in walk(self.tree):
            if node.object is not None:
                cmds.append(_command_js(node.object))
            cmds.extend(_command_js(p) for p in node.properties)
            if node.transform is not None:
                cmds.append(_command_js(node.transform))
        if self.animation is not None:
            cmds.append(_command_js(self.animation))
        js = (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")
        return ("<!DOCTYPE html>\n<html>\n<head><meta charset=utf-8><title>" + html_mod.escape(title)
                + "</title></head>\n<body>\n<div id=\"meshcat-pane\"></div>\n<script>\n" + js
                + "\n</script>\n<script>\nvar viewer = new MeshCat.Viewer(document.getElementById(\"meshcat-pane\"));\n"
                + "".join(cmds) + "\n</script>\n<style>body {margin: 0;} #meshcat-pane {width: 100vw; height: 100vh; "
                "overflow: hidden;}</style>\n" + extra_body + "\n</body>\n</html>\n")

    # --- inspection
    def node(self, path: str):
        """The tree node at ``path`` (``/meshcat/robot``) or None."""
        node = self.tree
        for p in [p for p in path.split("/") if p]:
            if p not in node:
                return None
            node = node[p]
        return node

    def object_paths(self) -> list[str]:
        """Paths of every node holding an object."""
        out: list[str] = []

        def rec(node, prefix):
            for k, v in node.items():
                p = f"{prefix}/{k}"
                if v.object is not None:
                    out.append(p)
                rec(v, p)

        rec(self.tree, "")
        return out

    def properties(self, path: str) -> dict:
        """Properties set on ``path`` (last value wins), e.g. ``{"visible": False}``."""
        import umsgpack

        node = self.node(path)
        out: dict = {}
        for p in (node.properties if node is not None else []):
            d = umsgpack.unpackb(p)
            out[d["property"]] = d["value"]
        return out

    def object_dict(self, path: str) -> dict | None:
        """The lowered ``set_object`` command of ``path``."""
        import umsgpack

        node = self.node(path)
        return umsgpack.unpackb(node.object) if node is not None and node.object is not None else None

    def replay(self, window: Any) -> None:
        """Send every recorded command, in order, to another meshcat window (a live server)."""
        for d in self.commands:
            window.send(_Lowered(d))

    # --- meshcat window interface
    def get_image(self, *args, **kwargs):
        raise PinKpiOedError("the recorded scene has no browser attached: write it as an HTML page or view it live")

    def open(self) -> SceneRecorder:
        return self

    def close(self) -> None:
        pass

    def wait(self) -> str:
        return "ok"
