"""Reference cases for ``iceresist validate``: one module per case, each following :mod:`iceresist.validate.result`."""
