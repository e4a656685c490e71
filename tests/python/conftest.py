"""The module's tests (`make test-python`)."""

import signal

# Tests send SIGINT to themselves and to their subprocesses, as Ctrl-C does. A shell that starts
# this run in the background without job control has SIGINT ignored (POSIX), and every child
# would inherit that: Python then never raises KeyboardInterrupt. Give this process Python's own
# handler, which its children get back as the default action when they start.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
