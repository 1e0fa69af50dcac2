//! `seqnet`: A hand-written LSTM with backpropagation through time, batched GEMM kernels, Adam/SGD training.
