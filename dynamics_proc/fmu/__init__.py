"""FMUs: the models standing in for the built-in ones (docs/fmu.md) and the dynamics role driven from outside
(the world exported as an FMU)."""
