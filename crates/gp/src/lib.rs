//! `gp`: Gaussian-process regression with ML-II hyper-parameter fitting (squared-exponential, Matern 5/2, white noise, universal kriging).
