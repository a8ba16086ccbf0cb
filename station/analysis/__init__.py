"""What a run's numbers say, pure of devices: the statistics of the readings, the
model the data can tell (``model_choice``), the verification's verdict and how many
cycles it needs (``sizing``), the accuracy at the tool (``accuracy_statement``,
``compensated``), the uncertainty budget (``run_budget``) and the lost motion
(``reversal``). The engine calls it; nothing here moves an axis."""
