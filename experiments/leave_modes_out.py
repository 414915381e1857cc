"""Leave modes out: fit on n = 1…6, predict n = 7…9.

Run: python experiments/leave_modes_out.py
Prints the prediction errors of least squares and of the posterior, and whether
each measured frequency lies inside its 95 % posterior predictive interval.
"""

import numpy as np

import ringfit  # noqa: F401
from ringfit.data import path
from ringfit.fit.least_squares import fit_natural_frequencies, fitted_ring
from ringfit.fit.posterior import natural_frequency_predictive, sample_posterior
from ringfit.io.modes import read_mode_table
from ringfit.io.tyre import read_tyre
from ringfit.physics.natural import natural_frequencies

TRAIN, TEST = range(1, 7), np.arange(7, 10)


def main(prior="physical"):
    table = read_mode_table(path("free-ssi.modes.csv"))
    tyre = read_tyre(path("table9.tyre.toml"))
    lsq = fit_natural_frequencies(table, tyre.geometry, tyre.ring, prior=prior, modes=TRAIN)
    post = sample_posterior(table, tyre.geometry, tyre.ring, prior=prior, modes=TRAIN, progress=False)
    measured = np.array([table.freq_hz[table.n == k][0] for k in TEST])
    lsq_hz = np.asarray(natural_frequencies(fitted_ring(lsq), tyre.geometry, TEST))
    pred = natural_frequency_predictive(post, TEST)
    print(f"fit on n = 1…6 ({lsq.status}, prior {prior}); predict n = 7…9\n")
    print(f"{'n':>3}{'measured':>10}{'LSQ':>9}{'error':>8}{'post. median':>14}{'95 % predictive':>20}{'inside':>8}")
    inside = []
    for i, k in enumerate(TEST):
        ok = pred["lo"][i] <= measured[i] <= pred["hi"][i]
        inside.append(ok)
        print(f"{k:>3}{measured[i]:>10.1f}{lsq_hz[i]:>9.2f}{lsq_hz[i] - measured[i]:>+8.2f}{pred['median'][i]:>14.2f}"
              f"{pred['lo'][i]:>10.1f} – {pred['hi'][i]:<7.1f}{'yes' if ok else 'NO':>6}")
    err = lsq_hz - measured
    print(f"\nmax |error| {np.max(np.abs(err)):.2f} Hz, RMS {np.sqrt(np.mean(err**2)):.2f} Hz; "
          f"{sum(inside)} of {len(TEST)} inside their 95 % interval")
    return err, inside


if __name__ == "__main__":
    main()
