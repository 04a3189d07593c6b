"""The master control: transport orders, dispatching, routing and traffic control over VDA 5050
(docs/master.md)."""
