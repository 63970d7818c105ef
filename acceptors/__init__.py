"""Acceptor plugins (``dispatch.acceptors`` entry points): how riders answer the offers a
decision makes them (see :mod:`dispatch.api.acceptor`): ``always`` accepts every offer,
``threshold``
declines past a wait or a detour, ``logit`` draws a choice from a binary logit model of the
wait, the in-vehicle time and the fare."""
