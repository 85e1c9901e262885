"""The commands besides ``sample`` and ``batch``: ``info``, ``check``, ``bench``, ``merge``
and ``preview``."""
