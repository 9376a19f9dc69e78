"""The paper's evaluation (Tables I-III, Figs. 5-10) and Table IV, as one command."""
