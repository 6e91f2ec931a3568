"""Benchmarks that load a trained policy or run training: ``python -m train.bench <name>``.

- ``training`` (:mod:`train.bench.training`): PPO training throughput on the four-finger env;
- ``fidelity`` (:mod:`train.bench.fidelity`): what coarser physics changes in one policy step;
- ``transfer`` (:mod:`train.bench.transfer`): policies trained at 2 and 2.5 ms under other
  physics;
- ``shield accuracy|latency|effect`` (:mod:`train.bench.shield_accuracy`,
  :mod:`train.bench.shield_latency`, :mod:`train.bench.shield_effect`, what they share in
  :mod:`train.bench.shield_common`): the QP grasp shield's linearisation against MuJoCo, its
  wall time per step and its effect on episodes.

They live here, above ``envs`` and ``shields`` (nothing below ``train`` imports ``train``);
the env-only throughput table stays ``python -m envs.bench``. ``python -m train.bench
--help`` lists the subcommands, ``python -m train.bench <name> --help`` their options.
"""
