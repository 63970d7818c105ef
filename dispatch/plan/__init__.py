"""The engine's plan layer: tasks and their sources, vehicles and the fleet, a vehicle's stops and
the
one schedule rule (with its compiled kernel and the insertion), the operator that drives plans and
the executions that move vehicles."""
