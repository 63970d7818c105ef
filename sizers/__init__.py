"""Fleet-sizing strategies (``dispatch.sizers`` plugins; the contract is
:mod:`dispatch.api.sizer`)."""
