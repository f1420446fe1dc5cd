#include "core/kernels.h"

#include <stdexcept>

namespace ganache {

CubicSpline::CubicSpline(Real supportRadius) : m_h(supportRadius), m_invH(1 / supportRadius) {
    if (!(supportRadius > 0) || !std::isfinite(supportRadius))
        throw std::invalid_argument("CubicSpline: support radius must be positive and finite");
    const Real h3 = m_h * m_h * m_h;
    m_k = Real(8) / (Real(M_PI) * h3);
    m_l = Real(48) / (Real(M_PI) * h3);
}

Real latticeKernelSum(Real spacing, const CubicSpline& w) {
    const int m = int(std::ceil(w.supportRadius() / spacing));
    Real sum = 0;
    for (int k = -m; k <= m; ++k)
        for (int j = -m; j <= m; ++j)
            for (int i = -m; i <= m; ++i) sum += w.W(spacing * Vec3(i, j, k));
    return sum;
}

}  // namespace ganache
