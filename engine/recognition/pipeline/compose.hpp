// The methods as compositions of stages, declared in one place (compose.cpp), read like
// Algorithm 1: the scene; the candidate sources; the screening; the method's selection (which
// refines and evaluates); the answer.
#pragma once

#include "engine/recognition/pipeline/stage.hpp"

#include <string>
#include <string_view>
#include <vector>

namespace ts::inline recognition::pipeline {

/// The stage names of a method, in order.
std::vector<std::string_view> method_stages(Method m);

/// Every stage name compose() knows.
std::vector<std::string_view> known_stages();

/// The pipeline of these stage names; an unknown name is an Error naming it (field
/// "pipeline.stages").
Pipeline compose(const std::vector<std::string_view>& names);

}  // namespace ts::recognition::pipeline
