"""Training and everything that loads a trained policy (the top layer: nothing imports it).

Commands: ``python -m train.ppo`` (the four-finger rotation main job; ``islands``: PPO on
the islands-and-bridges toy), ``python -m train.islands`` (the islands benchmark),
``python -m train.rollout`` (recorded episodes), ``python -m train.gait`` (gait strip),
``python -m train.compare`` (runs side by side), ``python -m train.bench <name>`` (training,
fidelity, transfer and grasp shield benchmarks), ``python -m train.shield_study`` (training
with and without each shield: does a shield help the hand learn?).

Modules: :mod:`~train.trainer` (the one PPO trainer: config, run directory, seeds, envs,
model, callbacks, evaluation), :mod:`~train.rotation` and :mod:`~train.islands_ppo` (the two
tasks it runs), :mod:`~train.options` (configs as command lines and config.json),
:mod:`~train.sb3` (SB3 plumbing the tasks share), :mod:`~train.evaluation` (the one
evaluation loop), :mod:`~train.policy` (loading and evaluating shipped policies),
:mod:`~train.seeding`, :mod:`~train.stats`, :mod:`~train.vec` and :mod:`~train.pipeline`
(seeds, intervals, worker processes, pipelined rollouts).
"""
