// Transitional: the shape prior is engine/recognition/shape_prior.hpp (it reads a Database and
// scores a Scene, so it sits above both). This forwarding header stays only until
// engine/recognition/recognizer.hpp includes the new path (issue 55); then delete it.
#pragma once

#include "engine/recognition/shape_prior.hpp"
