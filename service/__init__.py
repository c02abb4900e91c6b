"""The wavecore web service: a FastAPI app over ``wavecore``'s public API.

Build the app with :func:`service.app.create_app`; every limit lives in
:class:`service.settings.Settings` (``WAVECORE_*`` environment variables).
"""
