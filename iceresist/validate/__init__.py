"""Error against run time and stability of the method (issue: error against run time and stability).

Each reference case is a module in :mod:`iceresist.validate.cases` with the protocol of :mod:`.result`.
"""
