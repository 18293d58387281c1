"""Physical constants in the units nlosplan uses (metres, picoseconds)."""

#: Speed of light in vacuum, metres per picosecond.
C_M_PER_PS: float = 299_792_458.0 * 1e-12

#: Largest value a TMF8828 histogram bin register can hold (24 bits).
MAX_COUNT_24BIT: int = 2**24 - 1

#: Gaussian FWHM = FWHM_PER_SIGMA * sigma.
FWHM_PER_SIGMA: float = 2.3548200450309493
