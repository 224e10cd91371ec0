"""What the outside checks of #33 share: running a tool quietly and reading a 16 kHz WAV."""
import subprocess
import numpy as np
from scipy.io import wavfile

RATE = 16000


def run(cmd):
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def read(path):
    """The first channel of a 16 kHz WAV as float64 in [-1, 1)."""
    r, x = wavfile.read(path)
    assert r == RATE, (path, r)
    if x.dtype == np.int16:
        x = x.astype(np.float64) / 32768
    return x.astype(np.float64) if x.ndim == 1 else x[:, 0].astype(np.float64)
