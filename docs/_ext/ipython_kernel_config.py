"""IPython kernel configuration for the tutorials the docs build runs (``docs/conf.py`` puts
it in a private IPython directory for the build's kernels only).

The kernels talk to Sphinx over TCP on 127.0.0.1 (jupyter_client's default), and ipykernel 7
warns once per kernel that the link is not encrypted: seven identical lines in every build,
about a link that never leaves the machine. This filter drops that one message from the
kernel application's log; every other message of the kernels still shows.
"""

import logging


class _LocalTcpNotice(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "running over TCP without encryption" not in record.getMessage()


logging.getLogger("IPKernelApp").addFilter(_LocalTcpNotice())
