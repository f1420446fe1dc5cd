#pragma once
// Log-log charts for `ganache study`, drawn with the preview renderer's pixel font.

#include "render/render.h"

#include <string>
#include <utility>
#include <vector>

namespace ganache {

/// One line of a chart: points joined in the order given, each with an optional label.
struct ChartSeries {
    std::string label;
    std::vector<std::pair<Real, Real>> points;  ///< (x, y), both > 0 on logarithmic axes
    std::vector<std::string> pointLabels;       ///< empty, or one per point
    Vec3 colour = Vec3(0.2, 0.2, 0.2);
};

struct Chart {
    std::string title, xLabel, yLabel;
    std::vector<ChartSeries> series;
    int width = 1200, height = 800;
};

/// A chart with logarithmic axes spanning whole decades around every point, a grid at each decade, the series
/// as lines with square markers, and a legend. Points that are not finite and positive are left out.
Image logLogChart(const Chart& chart);

/// Distinct colours for chart series, by index.
Vec3 seriesColour(std::size_t index);

}  // namespace ganache
