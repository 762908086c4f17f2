# fenicsx_drape: the reference stack is Debian unstable's DOLFINx (>= 0.10 is required:
# older versions tear a branching truss mesh apart under MPI).
FROM debian:sid

# The local build passes "-o Acquire::Check-Valid-Until=false" for a frozen archive mirror.
ARG APT_OPTS=""
# Open MPI may run as root in the container and start more ranks than cores
# (Open MPI 4 reads the OMPI_ variable, Open MPI 5 and 6 the PRTE_ one).
ENV DEBIAN_FRONTEND=noninteractive \
    OMPI_ALLOW_RUN_AS_ROOT=1 \
    OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    OMPI_MCA_rmaps_base_oversubscribe=1 \
    PRTE_MCA_mapby=:oversubscribe \
    OMP_NUM_THREADS=1 \
    MPLBACKEND=Agg

# gcc and python3-dev: FFCx compiles forms at run time; python3-h5py: meshio's XDMF files;
# pytest-xdist: `make test` runs the serial tests on every core; pytest-timeout: a test that runs
# too long fails by its name; diskcache: the forming runs' cache; tomli-w: TOML files written.
# Sphinx, MyST-NB, Jupytext and a kernel: `make docs` executes the demos as pages.
RUN apt-get $APT_OPTS update \
 && apt-get $APT_OPTS install -y --no-install-recommends \
      python3-dolfinx python3-gmsh python3-meshio python3-petsc4py python3-mpi4py \
      python3-numpy python3-scipy python3-matplotlib python3-pytest python3-hypothesis \
      python3-h5py python3-pip python3-setuptools ruff mpi-default-bin gcc python3-dev make \
      python3-pytest-xdist python3-pytest-timeout python3-diskcache python3-tomli-w \
      python3-sphinx python3-myst-nb python3-jupytext python3-ipykernel python3-sphinx-book-theme \
 && rm -rf /var/lib/apt/lists/*

# Fail loudly on a DOLFINx that cannot distribute a branching truss.
RUN python3 -c "import dolfinx, sys; v = tuple(int(p) for p in dolfinx.__version__.split('.')[:2]); \
print('DOLFINx', dolfinx.__version__); sys.exit(0 if v >= (0, 10) else 'DOLFINx >= 0.10 required')"

WORKDIR /opt/fenicsx_drape
COPY pyproject.toml README.md ./
COPY fenicsx_drape ./fenicsx_drape
COPY demos ./demos
COPY meshes ./meshes
RUN pip install --break-system-packages --root-user-action=ignore --no-deps --no-build-isolation \
      -e . \
 && python3 -c "import fenicsx_drape; print('fenicsx_drape', fenicsx_drape.__version__)"

CMD ["python3", "-m", "fenicsx_drape", "form", "hemisphere", "--out", "results/hemisphere"]
