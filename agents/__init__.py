"""The agents: baselines, trainer, evaluation and experiments on the Memory Gym environments (:mod:`envs`).

A house of rooms along the data's way, one job each. Imports run only downwards, floor by floor, and no module
imports one that imports it back (``tests/agents/test_layout.py`` checks both). Floors, top first:

* :mod:`agents.cli`: the command lines (``memgym-train``, ``memgym-evaluate``, ``memgym-sweep``, ``memgym-plot``;
  ``scripts/`` holds their thin wrappers and the project's other tools, one floor higher);
* :mod:`agents.experiments`: sweeps, a grid expanded into runs, launched locally or on SLURM, a panel's results;
* :mod:`agents.training`: rollout storage, sequences, the PPO update, the trainer and what a run writes;
* :mod:`agents.evaluation`: a policy on novel seeds, one record per episode; record files; GIFs;
* :mod:`agents.analysis` and :mod:`agents.policy`, side by side (neither imports the other): from records to
  IQM scores, tables and figures; the actor-critic, the one acting loop, HELM, checkpoints;
* :mod:`agents.runtime`: atomic files, provenance, fault injection, pre-emption, tracking, the device;
* :mod:`agents.config`: the typed config from YAML (schema, loading, grids, the resume rule);
* :mod:`agents.memory`: the memory modules and their one registry;
* :mod:`agents.settings` and :mod:`agents.layers`: small shared modules (typed settings; weight initialisation);
* below them all, :mod:`envs`, which imports nothing of the agents.

Each room's ``__init__`` says what lives there and exports its public names. This module holds no code.
"""
