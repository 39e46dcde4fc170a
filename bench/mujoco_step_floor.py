"""How far the MuJoCo plant's own step (test/mujoco_plant/, 0.25 ms RK4) moves its next apexes, against the noise
floor the diagnosis is asked to come within 2 x of (issue 28's acceptance).

    python bench/mujoco_step_floor.py FOLDER [--finer N] [--strides S] [name ...]

Each stride is run twice from the same apex state (MuJoCo's integration state, the servo's and the controller's):
at the plant's step and at 1/N of it (N = 16). The next apexes' differences, in the model's metrics E_p/E_v/E_t
(4.1)-(4.3), are what the plant's discretisation alone adds to any continuous-time model's error; beside them the
noise floor of the recording (bench/mujoco_ablation.py's scoring, records what is missing in FOLDER). The apex is
taken back from the first step past it ballistically (z' = 0 between steps). test/mujoco_plant/ is not changed.
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
PLANT = REPO / "test" / "mujoco_plant"

HOPPER_STATE = ("phase", "servo_on", "swing", "cmd", "tau_cmd", "n_step", "hold_from", "t_off")


class Twin:
    """One plant run stride by stride, each stride also run at a finer step from the same start."""

    def __init__(self, name: str):
        import mujoco
        import suite
        from controller import Controller
        from nominal import load_nominal
        from sim import Hopper

        self.mujoco = mujoco
        self.nominal = load_nominal()
        self.controller = Controller(self.nominal, np.random.default_rng(suite.SEEDS[name] + 2))
        self.hopper = Hopper(suite.VARIANTS[name], self.nominal)
        self.hopper.steps_per_log = 1 << 30           # no log: only the apexes are compared
        self.model, self.data = self.hopper.robot.model, self.hopper.robot.data
        self.step = self.model.opt.timestep
        self.spec = mujoco.mjtState.mjSTATE_INTEGRATION

    def throw(self):
        ctl = self.controller
        height, speed = ctl.throw_state()
        ctl.new_run()
        self.hopper.throw(0.0, 0.0, height, speed, ctl.plan(height, speed))

    def _save(self):
        state = np.empty(self.mujoco.mj_stateSize(self.model, self.spec))
        self.mujoco.mj_getState(self.model, self.data, state, self.spec)
        return state, {k: copy.copy(getattr(self.hopper, k)) for k in HOPPER_STATE}, copy.deepcopy(self.controller)

    def _restore(self, saved):
        state, hopper, controller = saved
        self.mujoco.mj_setState(self.model, self.data, state, self.spec)
        self.mujoco.mj_forward(self.model, self.data)
        for key, value in hopper.items():
            setattr(self.hopper, key, copy.copy(value))
        self.controller = copy.deepcopy(controller)

    def _next_apex(self, step: float):
        """(height, forward position, forward speed, time) of the next apex at this step."""
        self.model.opt.timestep = step
        self.hopper.stride(self.controller)
        y, z, vy, vz = self.hopper.robot.yz()
        g = self.nominal.g
        return z + vz * vz / (2 * g), y - vy * vz / g, vy, self.data.time + vz / g

    def stride(self, finer: int):
        """The next apex at 1/finer of the plant's step and at its own (the run goes on from the latter), with the
        stride's start (forward position, time)."""
        saved = self._save()
        start = (self.hopper.robot.yz()[0], self.data.time)
        fine = self._next_apex(self.step / finer)
        self._restore(saved)
        return self._next_apex(self.step), fine, start


def step_errors(name: str, finer: int, strides: int) -> dict:
    """Mean E_p/E_v/E_t [%] of the plant at its step against 1/finer of it, over `strides` strides."""
    from sim import StrideFailure

    twin = Twin(name)
    twin.throw()
    ep, ev, et = [], [], []
    while len(ep) < strides:
        try:
            (z, y, v, t), (z_f, y_f, v_f, t_f), (y0, t0) = twin.stride(finer)
        except StrideFailure:
            twin.throw()
            continue
        ep.append(100 * math.hypot(z - z_f, y - y_f) / math.hypot(z_f, y_f - y0))
        ev.append(100 * abs(v - v_f) / abs(v_f))
        et.append(100 * abs(t - t_f) / abs(t_f - t0))
    return {"E_p": float(np.mean(ep)), "E_v": float(np.mean(ev)), "E_t": float(np.mean(et)),
            "step_us": twin.step * 1e6}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("names", nargs="*", default=["mj_clean", "mj_default", "mj_stiff_contact"])
    parser.add_argument("--finer", type=int, default=16)
    parser.add_argument("--strides", type=int, default=20)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(PLANT))
    sys.path.insert(0, str(REPO / "bench"))
    import mujoco_ablation

    args.folder.mkdir(parents=True, exist_ok=True)
    for name in args.names:
        step = step_errors(name, args.finer, args.strides)
        floor = mujoco_ablation.score(mujoco_ablation.record(args.folder, name), {}, {})["floor"]
        print(f"{name:18s} step {step['step_us']:g} us against 1/{args.finer}: E_p {step['E_p']:.3f} "
              f"E_v {step['E_v']:.3f} E_t {step['E_t']:.3f} % | noise floor {floor['E_p']:.3f} {floor['E_v']:.3f} "
              f"{floor['E_t']:.3f} | x floor " + "/".join(f"{step[k] / floor[k]:.1f}" for k in ("E_p", "E_v", "E_t")),
              flush=True)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main(sys.argv[1:]))
