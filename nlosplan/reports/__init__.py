"""Report assembly: plots (matplotlib) and tables. Computes no results."""

from nlosplan.reports.histogram_plot import plot_zone_histograms

__all__ = ["plot_zone_histograms"]
