"""The in-memory robot graph: topics, services, actions, parameters and types."""
