"""One rotation env over several objects: ``ihm/FourFingerRotateMixed-v0``.

:class:`MixedObjectRotate` holds one :class:`~envs.four_finger.env.FourFingerRotate` per
object, all with the same settings, and at every reset draws the object of the episode from
``np_random``, uniformly or with the weights of
:meth:`MixedObjectRotate.set_object_weights`. The policy is not told which object it holds:
the observation, the action and the reward are the drawn env's own (the spaces of every
object are the same), so a policy has to tell the sphere, the cylinder and the cube apart
from what the hand senses. ``info["object"]`` names the drawn object for logging and
evaluation; ``options={"object": name}`` at a reset picks one. With ``privileged=True`` the
critic's privileged state (after the env's own :data:`~envs.four_finger.N_PRIVILEGED`
entries) ends with the object's one-hot code over ``objects``: a value net that does not
know the object averages the sphere's long episodes with the cylinder's and cube's drops.

Each object's env keeps its own start grasps, failure replay buffer and randomised physics;
the settings are the env's groups (``reward``, ``sim``, ``starts``, ``observation``),
``randomize`` or ``physics`` as in ``FourFingerRotate``. Turned starts
(``starts.turned_prob``) are the cube's: the other objects start without them.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from envs.four_finger.env import FourFingerRotate
from envs.four_finger.physics import TRAIN_OBJECTS, FourFingerError, scene_name
from envs.four_finger.randomize import Randomization
from envs.four_finger.settings import StartSettings

__all__ = ["MixedObjectRotate"]


class MixedObjectRotate(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """Rotate an object drawn per episode from ``objects`` (module doc).

    Parameters
    ----------
    objects : the objects (names of :data:`~envs.four_finger.OBJECTS`, distinct, at least
        one), default the three training objects.
    starts : :class:`~envs.four_finger.settings.StartSettings` for every object (turned
        starts only for the cube).
    **settings : the other keyword arguments of ``FourFingerRotate`` (``reward``, ``sim``,
        ``observation``, ``randomize``, ``physics``, ``render_mode``, field overrides),
        the same for every object.

    Attributes: ``envs`` (object name -> its env), ``objects``, ``current`` (the object of
    the episode), and the drawn env's ``model``, ``data`` and ``dt`` through properties.
    """

    metadata = FourFingerRotate.metadata

    def __init__(
        self,
        objects: tuple[str, ...] | list[str] = TRAIN_OBJECTS,
        *,
        starts: StartSettings | None = None,
        **settings: Any,
    ) -> None:
        objects = tuple(objects)
        if not objects or len(set(objects)) != len(objects):
            raise FourFingerError(f"objects must be distinct and at least one, got {objects!r}")
        for o in objects:
            scene_name(o)
        starts = StartSettings() if starts is None else starts
        self.objects = objects
        self.envs = {
            o: FourFingerRotate(
                o, starts=starts if o == "cube" else replace(starts, turned_prob=0.0), **settings
            )
            for o in objects
        }
        first = self.envs[objects[0]]
        for o, env in self.envs.items():
            if env.observation_space != first.observation_space:
                raise FourFingerError(f"{o}: its observation space differs from {objects[0]}'s")
        self.observation_space = first.observation_space
        self._onehot = (
            np.eye(len(objects), dtype=np.float32) if first.observation.privileged else None
        )
        if self._onehot is not None:
            space = first.observation_space
            lo = np.concatenate([space.low, np.zeros(len(objects), np.float32)])
            hi = np.concatenate([space.high, np.ones(len(objects), np.float32)])
            self.observation_space = gym.spaces.Box(lo, hi, dtype=np.float32)
        self.action_space = first.action_space
        self.render_mode = first.render_mode
        self.current = objects[0]
        self.weights = np.full(len(objects), 1.0 / len(objects))

    @property
    def env(self) -> FourFingerRotate:
        """The env of the current episode's object."""
        return self.envs[self.current]

    @property
    def model(self) -> Any:
        return self.env.model

    @property
    def data(self) -> Any:
        return self.env.data

    @property
    def dt(self) -> float:
        return self.env.dt

    def set_object_weights(self, weights: dict[str, float]) -> None:
        """Draw the objects of the next episodes with probabilities proportional to
        ``weights`` (object name -> weight >= 0, every object named, not all zero): an
        object curriculum (``train.adr``). The default is uniform."""
        w = np.array([float(weights.get(o, np.nan)) for o in self.objects])
        if set(weights) != set(self.objects) or not np.all(w >= 0) or not w.sum() > 0:
            raise FourFingerError(
                f"object weights must name {self.objects} with weights >= 0, not all 0; "
                f"got {weights!r}"
            )
        self.weights = w / w.sum()

    def set_randomization(self, randomize: Randomization) -> None:
        """Every object's :meth:`FourFingerRotate.set_randomization`."""
        for env in self.envs.values():
            env.set_randomization(randomize)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Draw the object (``options["object"]`` picks it), then reset its env with the rest
        of ``options``. A ``seed`` seeds the draw and, through it, every object's env."""
        super().reset(seed=seed)
        if seed is not None:
            for k, env in enumerate(self.envs.values()):
                env.reset(seed=int(np.random.SeedSequence([seed, k]).generate_state(1)[0]))
        options = dict(options or {})
        obj = options.pop("object", None)
        if obj is None:
            obj = self.objects[int(self.np_random.choice(len(self.objects), p=self.weights))]
        elif obj not in self.envs:
            raise FourFingerError(f"options['object'] must be one of {self.objects}, got {obj!r}")
        self.current = obj
        obs, info = self.env.reset(options=options or None)
        return self._with_code(obs), {**info, "object": obj}

    def _with_code(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        """``obs`` followed by the object's one-hot code when the critic is privileged."""
        if self._onehot is None:
            return obs
        return np.concatenate([obs, self._onehot[self.objects.index(self.current)]])

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._with_code(obs), reward, terminated, truncated, {**info, "object": self.current}

    def render(self) -> NDArray[np.uint8] | None:
        return self.env.render()

    def close(self) -> None:
        for env in self.envs.values():
            env.close()
