"""Estimation on plain numpy arrays: motion and measurement models, filters, fusion rules and bounds.

The package knows nothing of the environment (no module imports ``coloc_env``): each module can be used
from a notebook with arrays. Conventions shared by every module:

* Arrays carry arbitrary leading batch axes, copies first, then agents; a filter's state is a small
  dataclass; a model gives ``function``, ``jacobian``, ``covar`` and ``rvs`` (``estimators.models``).
* Noise is a **variance or a covariance** inside the library: a scalar noise parameter is a variance
  (named ``*_var``, in m^2, rad^2, dB^2, m^2/s^2 ...), a matrix one a covariance (``Q``, ``R``, ``cov``).
  A standard deviation appears only where the paper's parameter is one (a sigma in its tables): the
  parameter then says so in its name (``*_std``, ``sigma_*``, ``*_sigma``) and in its docstring, with its
  unit (m, rad, dB), and the function squares it where it builds a covariance.
* SI units, angles in radians; randomness only from a ``numpy.random.Generator`` passed in.
"""
