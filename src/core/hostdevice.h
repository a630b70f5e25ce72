// One annotation for the small math kernels that a CUDA backend will share with the CPU engines
// (patch evaluation, box tests, the Newton step, sample generation): `__host__ __device__` under nvcc,
// plain `inline` elsewhere.
#pragma once

#if defined(__CUDACC__)
#define TESSERA_HD __host__ __device__ inline
#else
#define TESSERA_HD inline
#endif
