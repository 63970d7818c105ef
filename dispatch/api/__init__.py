"""All a plugin author reads: the data a decision exchanges (problem), the allocator and planner
contracts, the space contract, the registry, and one contract module per further plugin kind
(acceptor, charger, repositioner, sizer), with the small types they speak in (legs, voxels,
motion, comms) and the decentralized rounds decentralized allocators share."""
