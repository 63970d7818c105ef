"""Mode choice plugins (``dispatch.mode_choices`` entry points; contract:
:mod:`dispatch.api.mode_choice`)."""
