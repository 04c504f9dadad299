"""The batch wing: `rscalib batch` runs many single commands (one manifest row each) on Dask.

manifest.py reads the manifest into jobs (argv of the single command); store.py is the SQLite
results store; runner.py runs the jobs on a Dask cluster, one subprocess per job; summary.py writes
index.html. It may import cli (the commands' own parser) and io/base; engines never import it.
"""
