"""The paper study (Zhou, Gao, Zhang, Actuators 2024): its Tables 1-6, the reproduction page, the
paper's gains at fine steps, the calibration, the null models and predictors, and Theorem 1."""
