"""Training scripts: ``python -m train.ppo`` (PPO on a shielded env) and
``python -m train.islands`` (the islands-and-bridges benchmark)."""
