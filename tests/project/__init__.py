"""The package's top-level modules and repository-wide checks: the wheel and the public
API, the CI workflow, the FuseSoC cores, docs/cli.md, the Dask cluster (``raplas_hdl.cluster``)."""
