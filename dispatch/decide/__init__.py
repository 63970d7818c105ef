"""A decision: the dispatcher's loop, the pipeline that builds an allocator's problem, the cuts and
costs it uses, the answer checks, meeting points, offers and prebooking."""
