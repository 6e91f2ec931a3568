"""Automatic domain randomisation: ranges that widen as the policy holds on.

The training envs draw their physics from :class:`envs.four_finger.Randomization` shrunk
towards nominal by a scale ``s`` in (0, 1] (:meth:`~envs.four_finger.Randomization.scaled`).
:class:`AdrCallback` starts at the config's ``range_scale`` and, every ``adr_every`` env
steps, looks at the training episodes that ended since its last decision:

- drop rate ``<= adr_widen``: ``s += adr_step`` (at most 1, the full ranges);
- drop rate ``> adr_narrow``: ``s -= adr_step`` (at least the starting scale);
- otherwise, or with fewer than ``MIN_EPISODES`` episodes: ``s`` stays.

With ``objects`` (a mixed-object run, :class:`envs.four_finger.MixedObjectRotate`) and an
object share ``f > 0`` the same decision also sets the objects' draw: object ``o`` is drawn
with probability ``(1 - f) / n + f d_o / sum(d)``, ``d_o`` its episodes' drop rate since the
last decision (uniform when none dropped), so that the objects the policy drops are trained
on more, and none less than ``(1 - f) / n``.

It is the curriculum of OpenAI's ADR (Akkaya et al. 2019) on one scale for the four ranges
(friction, torsional friction, mass, gains); latency and noise are drawn at their full
values throughout. The decisions fall on multiples of ``adr_every`` steps, so a run that is
stopped and resumed makes them at the same steps. The schedule is ``adr.json`` in the run
directory: the current scale and one row per decision (steps, scale before and after,
episodes, drop rate; with objects each one's episodes, drop rate and the weights set). A
resumed run reads it back, dropping the decisions made after the checkpoint it resumes from.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from envs.four_finger import Randomization
from train.rotation_config import TrainingRandomization

__all__ = ["MIN_EPISODES", "AdrCallback", "AdrState", "next_scale", "object_weights"]

MIN_EPISODES = 16  # episodes a decision needs; with fewer the scale stays


@dataclass
class AdrState:
    """The curriculum's state: the current ``scale`` and the decisions so far (dicts with
    ``steps``, ``scale_before``, ``scale``, ``episodes``, ``drop_rate``)."""

    scale: float
    history: list[dict[str, Any]] = field(default_factory=list)

    def save(self, path: Path) -> None:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps({"scale": self.scale, "history": self.history}, indent=1) + "\n")
        tmp.replace(path)

    @classmethod
    def load(cls, path: Path, start: float, upto: int) -> AdrState:
        """The state saved at ``path`` as it was at ``upto`` env steps (later decisions
        dropped), or a new one at ``start`` when there is no file."""
        if not path.is_file():
            return cls(start)
        rows = [r for r in json.loads(path.read_text())["history"] if r["steps"] <= upto]
        return cls(rows[-1]["scale"] if rows else start, rows)


def next_scale(
    scale: float, drops: int, episodes: int, step: float, widen: float, narrow: float, low: float
) -> float:
    """The scale after a decision (module doc): ``scale + step`` (at most 1) when the drop
    rate ``drops / episodes <= widen``, ``scale - step`` (at least ``low``) when it is above
    ``narrow``, else ``scale``; unchanged with fewer than :data:`MIN_EPISODES` episodes."""
    if episodes < MIN_EPISODES:
        return scale
    rate = drops / episodes
    if rate <= widen:
        return min(1.0, round(scale + step, 10))
    if rate > narrow:
        return max(low, round(scale - step, 10))
    return scale


def object_weights(
    drops: dict[str, int], episodes: dict[str, int], share: float
) -> dict[str, float]:
    """The objects' draw probabilities (module doc): ``(1 - share) / n + share d_o / sum(d)``
    with ``d_o = drops[o] / episodes[o]`` (0 for an object without episodes); uniform when
    no object dropped."""
    rate = {o: drops.get(o, 0) / e if (e := episodes.get(o, 0)) else 0.0 for o in episodes}
    total, n = sum(rate.values()), len(rate)
    if total <= 0:
        return {o: 1.0 / n for o in rate}
    return {o: (1.0 - share) / n + share * r / total for o, r in rate.items()}


class AdrCallback(BaseCallback):
    """Widens or narrows the training envs' ranges (module doc) as ``settings`` say: the full
    ranges and sampling probabilities (:meth:`TrainingRandomization.full_ranges`), the first
    scale ``range_scale``, ``adr_every`` [env steps], ``adr_step``, ``adr_widen`` and
    ``adr_narrow`` (:func:`next_scale`), and with ``objects`` the object curriculum's
    ``object_share`` (:func:`object_weights`; none without objects or with share 0); the
    state lives in ``run_dir/adr.json``. The envs must have ``set_randomization``
    (:class:`envs.four_finger.FourFingerRotate`, :class:`envs.four_finger.MixedObjectRotate`)."""

    def __init__(
        self, settings: TrainingRandomization, objects: Sequence[str], run_dir: Path
    ) -> None:
        super().__init__()
        self.share = settings.object_share
        self.objects = tuple(objects) if self.share > 0 else ()
        self.per_object = {o: [0, 0] for o in self.objects}  # episodes, drops
        self.base, self.start = settings.full_ranges(), settings.range_scale
        self.every, self.step = int(settings.adr_every), settings.adr_step
        self.widen, self.narrow = settings.adr_widen, settings.adr_narrow
        self.path = Path(run_dir) / "adr.json"
        self.state = AdrState(self.start)
        self.episodes = self.drops = 0
        self.next = 0

    def ranges(self) -> Randomization:
        """The ranges of the current scale."""
        return self.base.scaled(self.state.scale)

    def _apply(self) -> None:
        self.training_env.env_method("set_randomization", self.ranges())
        self.logger.record("adr/scale", self.state.scale)
        weights = self.state.history[-1].get("weights") if self.state.history else None
        if self.objects and weights:
            self.training_env.env_method("set_object_weights", weights)

    def _on_training_start(self) -> None:
        self.state = AdrState.load(self.path, self.start, self.num_timesteps)
        self.next = (self.num_timesteps // self.every + 1) * self.every
        self._apply()
        self.state.save(self.path)

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            if done:
                dropped = bool(info.get("dropped", False))
                self.episodes += 1
                self.drops += dropped
                if info.get("object") in self.per_object:
                    self.per_object[info["object"]][0] += 1
                    self.per_object[info["object"]][1] += dropped
        return True

    def _on_rollout_end(self) -> None:
        if self.num_timesteps < self.next:
            return
        self.next = (self.num_timesteps // self.every + 1) * self.every
        before = self.state.scale
        after = next_scale(before, self.drops, self.episodes, self.step, self.widen,
                           self.narrow, self.start)  # fmt: skip
        rate = self.drops / self.episodes if self.episodes else None
        self.state.history.append({
            "steps": int(self.num_timesteps), "scale_before": before, "scale": after,
            "episodes": self.episodes, "drop_rate": None if rate is None else round(rate, 4),
        })  # fmt: skip
        row = self.state.history[-1]
        if self.objects:
            eps = {o: v[0] for o, v in self.per_object.items()}
            drops = {o: v[1] for o, v in self.per_object.items()}
            row["objects"] = {o: [eps[o], round(drops[o] / eps[o], 4) if eps[o] else None]
                              for o in self.objects}  # fmt: skip
            row["weights"] = {
                o: round(w, 4) for o, w in object_weights(drops, eps, self.share).items()
            }
            self.per_object = {o: [0, 0] for o in self.objects}
        self.state.scale = after
        self.episodes = self.drops = 0
        self._apply()
        self.state.save(self.path)
