"""What a fleet does besides serving requests: batteries and charger visits, repositioning,
shifts and the fleet's size, where it starts, and faults."""
