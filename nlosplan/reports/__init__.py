"""Report assembly: plots (matplotlib) and tables. Computes no results."""

from nlosplan.reports.histogram_plot import plot_zone_histograms
from nlosplan.reports.simulation_plot import plot_simulation

__all__ = ["plot_simulation", "plot_zone_histograms"]
