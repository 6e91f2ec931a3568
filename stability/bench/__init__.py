"""Benchmarks of the stability methods, one module each, run as
``python -m stability.bench NAME [options]`` (the dispatcher: ``__main__.py``):

* ``planar``: the planar method against the thesis' Table tab:performance (state counts,
  enumeration and query times, m = 2..50);
* ``mip``: ``no_mdp`` and ``iterative`` on HiGHS and SCIP;
* ``refinement``: the thesis' table tab:data (refinement vs full resolution on one
  4-contact grasp);
* ``grasps``: the thesis' runtime table tab:comp_data (``modesearch`` and ``refinement`` on
  twelve generated grasps);
* ``hands``: random hand grasps, 3-6 contacts, every method's time and error against
  ``exact``;
* ``tradeoff``: time against error of every 3D method and setting, measured against
  ``exact``.

Each writes ``NAME.csv`` (:func:`stability.io.write_csv`) and ``NAME.png`` to ``--out``.
"""
