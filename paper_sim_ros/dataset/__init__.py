"""Datasets at scale (issue 17): a spec of scenarios and axes to sweep, expanded into runs
and executed as Ray tasks, one CPU each, on this machine or a cluster.

    paper_sim_dataset config/dataset_example.yaml --out out/dataset [--workers N]
    paper_sim_dataset SPEC --out DIR --address auto|HOST:PORT|ray://HOST:PORT

``spec`` reads and expands a spec, ``run`` is one run on a worker, ``outputs`` a run's
folder, ``batch`` the Ray tasks, ``manifest`` the manifest and summary, ``progress`` the
bar, ``cli`` the command line.
"""
