"""Grounds that send task codes beyond one byte, or out of range, for tests/net."""

from swarmbox.api import GroundAlgorithm


class WideCodeGround(GroundAlgorithm):
    """Sends each drone two reliable tasks coded ``BASE`` and ``BASE + 1`` from prep_once."""

    BASE = 1000

    def prep_once(self, ctx):
        for drone in sorted(ctx.reports):
            for k in range(2):
                ctx.send_task(drone, code=self.BASE + k, data=str(k))


class NegativeCodeGround(WideCodeGround):
    BASE = -5
