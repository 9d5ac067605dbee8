import os

import matplotlib

matplotlib.use("Agg")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# no background builds of the compiled loop from the tests (shevsim.warmup; a test turns it on itself)
os.environ.setdefault("SHEVSIM_BACKGROUND_COMPILE", "0")
