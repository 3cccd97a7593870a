"""Fire maps as images for the ground station: each agent's grid beside the true fire.

Grid messages are deltas against acknowledged messages (:mod:`agent.beliefs.grid_exchange`), so the observer
rebuilds every agent's grid exactly as a receiver does — one :class:`~agent.beliefs.grid_exchange.GridReceiver`
per (belief type, geometry) it has seen, created from the first keyframe's header. Images are north
up (row 0 is the northern edge), east to the right, coloured with a perceptual colour map from
probability 0 (dark) to 1 (bright).
"""

from __future__ import annotations

import numpy as np

from agent.beliefs.grid_exchange import GridReceiver
from agent.net import wire
from agent.net.fire_truth import decode_fire
from fusion.grid_geometry import GridGeometry
from fusion.grid_layers import GridLayers

COLOURMAP = "inferno"  # chosen here
TRUTH_COLOURS = np.array([[40, 40, 40], [255, 90, 0], [110, 70, 60]], np.uint8)  # unburnt, burning, burnt
#: The maps' legend (``maps/legend`` in the recording).
LEGEND = ("**Fire maps** — north up, east to the right.\n\n"
          "* `truth`: unburnt (dark grey), burning (orange), burnt (brown) cells.\n"
          f"* each agent's map: the cell's probability of fire, from 0 (black) to 1 (pale yellow), "
          f"matplotlib's `{COLOURMAP}` colour map.\n")


def _lut(name: str = COLOURMAP) -> np.ndarray:
    import matplotlib

    return (matplotlib.colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3] * 255).astype(np.uint8)


class GridImages:
    def __init__(self):
        self._decoders: dict[tuple, tuple[GridLayers, object]] = {}
        self._lut = _lut()

    def agent_image(self, origin: str, seq: int, payload: dict) -> np.ndarray:
        """RGB image of ``origin``'s grid in message ``seq``; raises :class:`agent.net.wire.DecodeError`."""
        if not isinstance(payload, dict) or payload.get("belief") not in ("logodds", "beta"):
            raise wire.DecodeError("grid_geometry", "a grid message names its belief type")
        try:
            geometry = GridGeometry.from_dict(payload.get("geometry"))
        except (ValueError, TypeError, AttributeError) as err:
            raise wire.DecodeError("grid_geometry", str(err)) from None
        key = (payload["belief"], repr(geometry))
        if key not in self._decoders:
            beliefs = GridLayers(payload["belief"], geometry)
            self._decoders[key] = (beliefs, GridReceiver(geometry.shape, beliefs.layers))
        beliefs, receiver = self._decoders[key]
        layers = receiver.decode(origin, seq, payload.get("grid"))
        try:
            probability = beliefs.from_layers(layers).probability()
        except ValueError as err:
            raise wire.DecodeError("grid_bad_values", str(err)) from None
        return self.colour(probability)

    def colour(self, probability: np.ndarray) -> np.ndarray:
        index = np.clip(np.rint(probability * 255.0), 0, 255).astype(np.uint8)
        return self._lut[index[::-1]]

    @staticmethod
    def truth_image(fire_payload) -> np.ndarray:
        """RGB image of the true fire (unburnt / burning / burnt), north up."""
        fire = decode_fire(fire_payload)
        return TRUTH_COLOURS[np.clip(fire.state, 0, 2)[::-1]]
