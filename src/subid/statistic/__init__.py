"""Statistics: the mergeable Hankel statistic every discrete-time method starts from."""

from subid.statistic.hankel import HankelStatistic

__all__ = ['HankelStatistic']
