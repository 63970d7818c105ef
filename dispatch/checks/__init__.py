"""``dispatch check`` and ``dispatch new``: the plugin checks, on random problems, and the plugin
scaffold."""
