"""Benchmarks of the stability methods, one module each, run as
``python -m stability.bench planar|mip|refinement|grasps|tradeoff`` (:mod:`.__main__`):

* :mod:`~stability.bench.planar`: the planar method against the thesis' Table
  tab:performance (state counts, enumeration and query times, m = 2..50);
* :mod:`~stability.bench.mip`: ``no_mdp`` and ``iterative`` on HiGHS and SCIP;
* :mod:`~stability.bench.refinement`: the thesis' table tab:data (refinement vs full
  resolution on one 4-contact grasp);
* :mod:`~stability.bench.grasps`: the thesis' runtime table tab:comp_data (refinement on
  twelve generated grasps);
* :mod:`~stability.bench.tradeoff`: time against error of every 3D method and setting,
  measured against ``exact``.

Each writes ``<name>.csv`` (:func:`stability.io.write_csv`) and ``<name>.png`` to
``--out``.
"""
