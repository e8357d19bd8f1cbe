"""Batch algorithms that probe the FleetAlgorithm contract and its failures (used by tests/api)."""

import numpy as np

from swarmbox.algorithms.hover import HoverFleet
from swarmbox.api import FleetAlgorithm, FleetSetpoints, Stage


class OrderedTasksFleet(FleetAlgorithm):
    """The batch twin of ``tests.core.algos.StatefulDrone``: insists on reliable tasks arriving in
    order, once each, in PREPARATION, after its drone's ``prep_once``; marks as the twin does."""

    def setup(self, fleet):
        self.received = [None] * fleet.n   # None until the drone's prep_once

    def prep_once(self, fleet, rows):
        for i in rows.tolist():
            self.received[i] = []
            fleet.ctx(i).mark("drone_prep_once", tick=fleet.ctx(i).tick)

    def on_task(self, fleet, i, task):
        ctx = fleet.ctx(i)
        if ctx.stage is not Stage.PREPARATION:
            raise AssertionError(f"task {task.data} delivered in {ctx.stage.name}")
        got = self.received[i]
        if task.code != len(got):
            raise AssertionError(f"task {task.code} delivered to row {i}, expected {len(got)} (got {got})")
        got.append(task.code)

    def prep_complete(self, fleet, rows):
        n = int(fleet.params.get("n_tasks", 40))
        enough = np.array([r is not None and len(r) >= n for r in self.received])
        return enough & fleet.ready_to_arm

    def exec_once(self, fleet, rows):
        for i in rows.tolist():
            fleet.ctx(i).mark("tasks", received=len(self.received[i]))

    def exec_loop(self, fleet, rows):
        return None

    def exec_complete(self, fleet, rows):
        return np.ones(fleet.n, dtype=bool)


class EveryOtherTick(HoverFleet):
    """Hover, but drone 0 gets a NaN row (no setpoint: its vehicle keeps the last) on odd ticks."""

    def exec_loop(self, fleet, rows):
        sp = super().exec_loop(fleet, rows)
        ned = sp.ned.copy()
        if fleet.stage_tick[0] % 2:
            ned[0] = np.nan
        return FleetSetpoints.position(ned)


class WrongShape(HoverFleet):
    def exec_loop(self, fleet, rows):
        return FleetSetpoints.position(self.target[:-1])


class PartlyNaN(HoverFleet):
    def exec_loop(self, fleet, rows):
        ned = self.target.copy()
        if fleet.stage_tick[2] > 5:
            ned[2, 1] = np.nan
        return FleetSetpoints.position(ned)


class NotBool(HoverFleet):
    def exec_complete(self, fleet, rows):
        return super().exec_complete(fleet, rows).astype(float)


class ReturnsSetpoint(HoverFleet):
    def exec_loop(self, fleet, rows):
        return fleet.ctx(0).pos_ned_m


class Raises(HoverFleet):
    def exec_complete(self, fleet, rows):
        raise KeyError("no such thing")


class WritesArrays(HoverFleet):
    def exec_loop(self, fleet, rows):
        fleet.pos_ned_m[0, 0] = 1.0
        return None


class BadKind(HoverFleet):
    def exec_loop(self, fleet, rows):
        return FleetSetpoints(np.full(fleet.n, 7), self.target)


class BadYaw(HoverFleet):
    def exec_loop(self, fleet, rows):
        return FleetSetpoints.position(self.target, np.zeros(fleet.n + 1))
