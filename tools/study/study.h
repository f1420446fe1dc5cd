#pragma once
// `ganache study`: what accuracy costs in time (see study.cpp and docs/study/report.md).

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace ganache {

struct StudyOptions {
    bool quick = false;                          ///< shorter runs, two settings per knob
    std::filesystem::path out = "out/study";     ///< study.csv, report.md, <case>.png
    std::filesystem::path scenes = "scenes/study";
    std::vector<std::string> cases;              ///< empty: every case
    int threads = 0;                             ///< 0: every core
    /// The signal that asks the study to stop (0: none); checked between steps and between runs.
    std::function<int()> stopSignal;
};

/// Runs the study and writes its CSV, charts and report; InputError for bad options.
void studyCommand(const StudyOptions& options);

}  // namespace ganache
